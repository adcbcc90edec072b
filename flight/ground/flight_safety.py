"""The streamer's two safety steps: install the fence before arming, restore parameters after.

`install_safety` runs once the vehicle has a position and passed its checks: the fence of
`mavsysid.flight.ground.geofence` (unless the operator said ``--no-fence``), recorded in
``meta.json`` (``fence``, and ``parameters`` with each changed name's original and flight
value, written at once so that a killed streamer leaves the originals on disk).

`restore_parameters` runs when the flight ends, fails or is interrupted: every parameter
the session's `ParameterSession` changed goes back, newest first, and then the fence
points the vehicle held before (`mavsysid.flight.ground.geofence.restore_fence_points`).
One exception: while the vehicle is still armed (hovering with ``--no-land``, held in
BRAKE/HOLD after an abort, landing after Ctrl-C) the fence, its points and the timeout
parameters stay in force, since switching a fence off under a flying vehicle is the wrong
way round; the line printed and ``meta.json`` say which ones and their original values.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from mavsysid.flight.ground.geofence import (
    FENCE_MARGIN,
    SAFETY_PARAMETERS,
    install_fence,
    restore_fence_points,
)
from mavsysid.flight.ground.mavlink_link import HeartbeatLost
from mavsysid.flight.ground.trajectory_safety import format_box

__all__ = ["before_arming", "install_safety", "put_back_fence_points", "restore_parameters"]


def _record(session: Any) -> dict[str, Any]:
    p = session.parameters
    out = {name: {"original": o, "flight": f, "restored": False}
           for name, (o, f) in p.changed.items()}
    out.update({name: {"original": o, "flight": f, "restored": True}
                for name, (o, f) in p.restored.items()})
    return out


def install_safety(session: Any, home: Sequence[float], say: Callable[[str], None]) -> None:
    """Install the fence for ``session``'s box (``home``: position on the ground, m ENU).

    Raises
    ------
    JobFailedError
        The vehicle has no working fence (unless ``settings.fence`` is off).
    """
    settings = session.settings
    if not settings.fence:
        say("warning: --no-fence: the box is enforced by the streamer only; if it dies, "
            "the vehicle flies on its last command until its own failsafe")
        session.note("fence", None)
        return
    try:
        record = install_fence(session.link, session.commands, session.parameters,
                               session.box, home, settings.fence_margin or FENCE_MARGIN, say)
    finally:
        session.note("parameters", _record(session))
    session.note("fence", record)


def before_arming(session: Any, home: Sequence[float]) -> str:
    """The line the operator reads before the vehicle arms: the box and where it came from,
    the fence (or none) and the take-off point (``home``, m ENU).

    Parameters
    ----------
    session : StreamSession
        The flight's session: its ``box`` ([x_min, y_min, z_min, x_max, y_max, z_max], m,
        world ENU), ``box_source``, and ``meta`` with the fence `install_safety` recorded
        (None with ``--no-fence``).
    home : sequence of 3 float
        The vehicle's position on the ground before take-off, m, world ENU.
    """
    fence = session.meta.get("fence")
    if fence:
        corners = fence["corners_enu_m"]
        xs, ys = [c[0] for c in corners], [c[1] for c in corners]
        shown = (f"{fence['kind']} x {min(xs):g}..{max(xs):g}, y {min(ys):g}..{max(ys):g} m, "
                 f"{fence['alt_max_m']:.1f} m above home")
    else:
        shown = "none (--no-fence)"
    x, y, z = (float(v) for v in home)
    return (f"box {format_box(session.box)} ({session.box_source}); fence {shown}; "
            f"take-off point x {x:.2f}, y {y:.2f}, z {z:.2f} m")


def put_back_fence_points(link: Any, fence: dict[str, Any] | None,
                          say: Callable[[str], None]) -> bool:
    """Put back the fence points a flight replaced (``fence`` as `install_safety` recorded it
    in ``meta.json``; updated in place). True when nothing is left to put back.

    Parameters
    ----------
    link : MavlinkLink
        The vehicle, disarmed.
    fence : dict or None
        ``meta.json``'s ``fence``: ``points_before`` (None: unknown), ``points_restored``.
    say : callable
        Receives a line when the points could not be put back.
    """
    if not fence or fence.get("points_restored", True):
        return True
    before = fence.get("points_before")
    if before is None:
        say("warning: the fence points the vehicle held before the flight are unknown; its "
            "fence points are the flight's")
        fence["points_restored"] = True
        return True
    try:
        problem = restore_fence_points(link, before)
    except HeartbeatLost as error:
        problem = str(error)
    if problem is not None:
        say(f"warning: the fence points were not put back ({problem})")
        return False
    fence["points_restored"] = True
    return True


def restore_parameters(session: Any, say: Callable[[str], None]) -> None:
    """Put back what the flight changed (see the module docstring); never raises."""
    params = getattr(session, "parameters", None)
    if params is None:
        return
    link = session.link
    if params.changed:
        _restore_changed(session, params, say)
    fence = session.meta.get("fence")
    if not link.vehicle.armed and fence and not fence.get("points_restored", True):
        if put_back_fence_points(link, fence, say):
            say(f"fence points restored: {len(fence.get('points_before') or [])} as before")
        session.note("fence", fence)


def _restore_changed(session: Any, params: Any, say: Callable[[str], None]) -> None:
    """The parameters (the safety ones left in force while the vehicle is armed)."""
    keep = ([n for n in params.changed if n in SAFETY_PARAMETERS]
            if session.link.vehicle.armed else [])
    try:
        problems = params.restore(keep=keep)
    except HeartbeatLost as error:  # a link gone while restoring: report, never raise
        problems = [f"could not restore the parameters: {error}"]
    if len(problems) > 1 and not params.restored:  # one cause (a lost link): one line
        problems = [f"{problems[-1]} (nor {', '.join(n for n in params.changed)})"]
    for line in problems:
        say(f"warning: {line}")
    if keep:
        say("warning: the vehicle still flies: fence and timeouts left in force ("
            + ", ".join(f"{n} was {params.changed[n][0]:g}" for n in keep)
            + "); once it has landed: mavsysid restore "
            + f"{getattr(session, 'directory', 'FLIGHT_DIR')} --connect "
            + f"{getattr(getattr(session, 'settings', None), 'connect', 'LINK')}")
    restored = params.restored
    if restored:
        say("parameters restored: " + ", ".join(f"{n} {o:g}" for n, (o, _f) in
                                                  restored.items()))
    session.note("parameters", _record(session))
