"""One ground-station flight: open the session for a trajectory file (plan checks, flight
directory, connection), fly it, download the vehicle's own log of it once landed
(``StreamSettings.download_log``), and return where it was recorded.

`run_stream` is what ``mavsysid stream`` and the demo call; tests call it directly.
`restore_flight_parameters` (``mavsysid restore``) puts back the parameters a flight's
``meta.json`` lists, after a streamer that could not (killed, link lost).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mavsysid.flight.ground.continuation import Continuation
from mavsysid.flight.ground.stream_session import StreamSession, StreamSettings, open_session
from mavsysid.flight.ground.streamer import fly

__all__ = ["RestoreOutcome", "StreamOutcome", "download_into_flight", "restore_flight_parameters",
           "run_stream"]


@dataclass(frozen=True)
class StreamOutcome:
    """A finished flight: its directory and the final metadata (``meta.json``)."""

    directory: Path
    meta: dict[str, Any]


def run_stream(trajectory: str | Path, settings: StreamSettings,
               vehicle: str | Path | None = None, say: Callable[[str], None] | None = None,
               progress: bool = True, at_end: Callable[[StreamSession], None] | None = None,
               continuation: Continuation | None = None) -> StreamOutcome:
    """Fly ``trajectory`` with ``settings`` (see `flight.ground.streamer.fly`, also for ``at_end``
    and ``continuation``).

    Parameters
    ----------
    trajectory : str or Path
        Trajectory file (`mavsysid.formats.trajectory_file`).
    settings : StreamSettings
        Connection, rates, guards and where the flight directory goes.
    vehicle : str or Path, optional
        Shipped vehicle name or TOML path; the configuration stored in the file by default.
    say : callable, optional
        Receives one-line status messages.
    progress : bool
        Show a progress bar while streaming.
    at_end : callable, optional
        Called with the session after the flight.
    continuation : callable, optional
        Further trajectories flown in the same run (`mavsysid.flight.ground.continuation`).

    Raises
    ------
    InputError
        Bad trajectory, vehicle, box or connection string.
    JobFailedError
        Refused or aborted; the flight directory keeps what was recorded.
    KeyboardInterrupt
        After the safe action.
    """
    say = say or (lambda _text: None)
    with open_session(trajectory, settings, vehicle) as session:
        session.commands.say = say
        say(f"recording into {session.directory}")
        fly(session, say, progress, at_end, continuation)
    meta = session.meta
    if settings.download_log and settings.land and meta.get("status") == "complete":
        meta = download_into_flight(session.directory, settings, say)
    return StreamOutcome(session.directory, meta)


def download_into_flight(directory: Path, settings: StreamSettings,
                         say: Callable[[str], None]) -> dict[str, Any]:
    """Download the landed vehicle's newest log into a flight directory; record it in its
    ``meta.json`` (``autopilot_log``, and ``files.autopilot_log``), or why it failed.

    Parameters
    ----------
    directory : Path
        The flight directory.
    settings : StreamSettings
        The link (connection, signing, speedup, lock-step, heartbeat timeout).
    say : callable
        Receives one-line messages; a failed download is a warning, not an error.

    Returns
    -------
    dict
        The flight's ``meta.json`` as written.
    """
    from mavsysid.flight.ground.log_download import download_flight_log
    from mavsysid.formats.flight_dir import read_meta, write_meta

    from mavsysid.errors import MavsysidError

    meta = read_meta(directory / "meta.json")
    try:
        log = download_flight_log(settings.connect, directory, settings.signing_key,
                                  settings.speedup, settings.lockstep,
                                  settings.heartbeat_timeout, say)
    except MavsysidError as error:
        say(f"warning: the vehicle's log was not downloaded: {error}")
        meta["autopilot_log"] = {"error": str(error)}
    else:
        meta["autopilot_log"] = log.summary()
        meta.setdefault("files", {})["autopilot_log"] = log.path.name
        state = "" if log.complete else f", incomplete ({log.received} of {log.size} bytes)"
        say(f"downloaded the vehicle's log {log.log_id} into {log.path} ({log.size / 1e6:.2f} "
            f"MB in {log.seconds:.1f} s, {log.rate / 1e3:.0f} kB/s{state})")
    write_meta(directory / "meta.json", meta)
    return meta


@dataclass(frozen=True)
class RestoreOutcome:
    """What `restore_flight_parameters` did.

    Attributes
    ----------
    restored : dict
        name → (value found on the vehicle, original value written back).
    unchanged : dict
        name → original value, already in place.
    read_back : dict
        name → value read from the vehicle afterwards.
    fence_points : int or None
        How many fence points were put back (0: the fence mission cleared, as before the
        flight); None when there were none to put back.
    """

    restored: dict[str, tuple[float, float]]
    unchanged: dict[str, float]
    read_back: dict[str, float]
    fence_points: int | None = None


def restore_flight_parameters(directory: str | Path, connect: str,
                              signing_key: bytes | None = None,
                              heartbeat_timeout: float = 30.0, land: bool = False,
                              land_timeout: float = 60.0,
                              say: Callable[[str], None] | None = None) -> RestoreOutcome:
    """Put back on the vehicle every parameter a flight's ``meta.json`` lists as changed,
    and the fence points it held before the flight.

    For a flight that ended without restoring them: a streamer killed (kill -9) or a link
    lost mid-flight. Each parameter is written to its ``original`` value unless it already
    holds it, then all are read back; the fence points (``fence.points_before``) are
    uploaded again, or the fence mission cleared when there were none. ``meta.json``
    records the restore.

    Parameters
    ----------
    directory : str or Path
        The flight directory (its ``meta.json``, ``parameters``).
    connect : str
        MAVLink connection to the vehicle (`MavlinkLink`).
    signing_key : bytes, optional
        MAVLink 2 signing key.
    heartbeat_timeout : float
        How long to wait for the vehicle's heartbeat, s.
    land : bool
        An armed vehicle is sent to LAND and its landing awaited first, to the disarm
        (`mavsysid.flight.ground.landing.wait_disarmed`); else it is refused.
    land_timeout : float
        Give up the landing after this long with the vehicle coming no lower, s.
    say : callable, optional
        Receives one-line status messages.

    Raises
    ------
    InputError
        No such flight directory, or an unreadable ``meta.json``.
    JobFailedError
        No vehicle, a vehicle still armed (without ``land``, or a landing that stalled),
        a parameter that could not be written or does not read back as its original
        value, or fence points that could not be put back.
    """
    from mavsysid.flight.ground.mavlink_link import MavlinkLink
    from mavsysid.formats.flight_dir import read_meta, write_meta

    say = say or (lambda _text: None)
    directory = Path(directory)
    meta = read_meta(directory / "meta.json")
    listed = meta.get("parameters") or {}
    originals = {name: float(entry["original"]) for name, entry in listed.items()
                 if isinstance(entry, dict) and "original" in entry}
    fence = meta.get("fence") if isinstance(meta.get("fence"), dict) else None
    points = None if fence is None or fence.get("points_restored", True) else fence
    if not originals and points is None:
        say(f"{directory / 'meta.json'} lists no changed parameters: nothing to restore")
        return RestoreOutcome({}, {}, {})
    link = MavlinkLink(connect, None, signing_key=signing_key)
    try:
        link.start_heartbeat()
        vehicle = link.wait_heartbeat(heartbeat_timeout, say)
        if vehicle.armed:
            _land_first(link, land, land_timeout, say)
        outcome = _write_back(link, originals)
        if points is not None:
            outcome = _restore_points(link, points, outcome, say)
    finally:
        link.close()
    for name in originals:
        listed[name]["restored"] = True
    meta["restored_by"] = {"command": "mavsysid restore", "connection": connect,
                           "written": sorted(outcome.restored),
                           "already_original": sorted(outcome.unchanged),
                           "fence_points": outcome.fence_points}
    write_meta(directory / "meta.json", meta)
    return outcome


def _write_back(link: Any, originals: dict[str, float]) -> RestoreOutcome:
    """Write each parameter's original value (newest first) and read them all back."""
    from mavsysid.flight.ground.parameter_session import ParameterSession

    from mavsysid.errors import JobFailedError

    if not originals:
        return RestoreOutcome({}, {}, {})
    params = ParameterSession(link)
    before = params.read(list(originals))
    missing = [n for n in originals if n not in before]
    if missing:
        raise JobFailedError(f"the vehicle did not answer for {', '.join(missing)}: "
                             "nothing restored")
    for name in reversed(list(originals)):  # newest first, as the streamer does
        params.set(name, originals[name])
    read_back = params.read(list(originals))
    wrong = [f"{n} reads {read_back.get(n, float('nan')):g}, not {v:g}"
             for n, v in originals.items() if not _same_value(read_back.get(n), v)]
    if wrong:
        raise JobFailedError("not restored: " + "; ".join(wrong))
    restored = {n: (before[n], v) for n, v in originals.items() if not _same_value(before[n], v)}
    unchanged = {n: v for n, v in originals.items() if n not in restored}
    return RestoreOutcome(restored, unchanged, read_back)


def _restore_points(link: Any, fence: dict[str, Any], outcome: RestoreOutcome,
                    say: Callable[[str], None]) -> RestoreOutcome:
    """The fence points of ``meta.json``'s ``fence`` put back (updated in place)."""
    from mavsysid.flight.ground.flight_safety import put_back_fence_points

    from mavsysid.errors import JobFailedError

    if not put_back_fence_points(link, fence, say):
        raise JobFailedError("the parameters are back, but not the fence points the vehicle "
                             "held before the flight")
    count = len(fence.get("points_before") or [])
    return RestoreOutcome(outcome.restored, outcome.unchanged, outcome.read_back, count)


def _land_first(link: Any, land: bool, land_timeout: float,
                say: Callable[[str], None]) -> None:
    """An armed vehicle: refused, or (``land``) sent to LAND and landed to the disarm."""
    from mavsysid.flight.ground.landing import LandingLimits, wait_disarmed
    from mavsysid.flight.ground.vehicle_commands import VehicleCommands

    from mavsysid.errors import JobFailedError

    if not land:
        raise JobFailedError("the vehicle is armed: restore once it has landed (or give "
                             "--land to land it first)")
    commands = VehicleCommands(link, say=None)
    home_up = _home_height(link, commands)
    if link.vehicle.mode != "LAND":
        commands.set_mode("LAND")
    say("the vehicle is armed: landing")
    if not wait_disarmed(link, commands, say, home_up, LandingLimits(stall=land_timeout)):
        raise JobFailedError("the vehicle did not land and disarm: nothing restored")


def _home_height(link: Any, commands: Any) -> float | None:
    """Home's height in the vehicle's local frame, m up (HOME_POSITION z), or None."""
    got: list[float] = []

    def listen(msg: Any, _t: float) -> None:
        if msg.get_type() == "HOME_POSITION":
            got.append(-float(msg.z))

    link.add_listener(listen)
    try:
        commands.request_message("HOME_POSITION")
        deadline = link.clock.now() + 3.0
        while not got and link.clock.now() < deadline:
            link.poll(0.05)
    finally:
        link.remove_listener(listen)
    return got[-1] if got else None


def _same_value(a: float | None, b: float) -> bool:
    """Equal as an autopilot stores them (float32)."""
    return a is not None and abs(a - b) <= 1e-6 * max(1.0, abs(b))
