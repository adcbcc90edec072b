"""One streamed flight's resources and records: link, recorder, stream, guards, meta.json.

`open_session` checks the plan (`mavsysid.flight.ground.preflight.check_plan`) before anything is
created, then makes ``<log_dir>/<UTC time>_<name>/`` with ``flight.tlog`` (both
directions, `MavlinkLink`), ``pose.csv`` (`TelemetryRecorder`) and ``meta.json``. When no
vehicle ever answers (no heartbeat), the session removes the directory as it closes.
``meta.json`` is live: while the flight runs it says ``"running": true`` with status
``aborted`` (and a reason saying the streamer never finished), rewritten about once a
second (sample count, ``updated``) and at each milestone (vehicle identified, telemetry
rates, trajectory start and end), from a thread of its own (`MetaWriter`: an ``fsync``
never delays a setpoint). The final write, at the end, says ``"running": false`` with
``complete`` or ``aborted`` and the real reason. So a killed streamer (kill -9) leaves a
meta.json that reads as aborted, with the samples of pose.csv up to about a second before
the kill, and both logs up to its last message: no clean-up needed.

While a session is open (on the main thread), SIGINT and SIGTERM do not strike at once:
the link raises `KeyboardInterrupt` from its next wait, so the flight can stop the stream
and act safely; a second signal interrupts immediately.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import shutil
import signal
import tempfile
import threading
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.meta_writer import MetaWriter, stream_flight_dir
from mavsysid.flight.ground.parameter_session import ParameterSession
from mavsysid.flight.ground.prearm import PrearmMonitor
from mavsysid.flight.ground.preflight import check_plan
from mavsysid.flight.ground.realtime import raise_priority, restore_scheduling
from mavsysid.flight.ground.stream_control import FlightGuards, SetpointStream
from mavsysid.flight.ground.telemetry_recorder import STAMPING, SetpointHistory, TelemetryRecorder
from mavsysid.flight.ground.trajectory_safety import flight_limits, operator_box
from mavsysid.flight.ground.vehicle_commands import VehicleCommands
from mavsysid.flight.mavlink_setup import parse_connect
from mavsysid.formats.flight_dir import STREAM_SOURCE
from mavsysid.formats.flight_log import software_version
from mavsysid.formats.trajectory_file import TrajectoryFile, read_trajectory
from mavsysid.vehicle.config import VehicleConfig, load_vehicle, vehicle_to_toml

__all__ = ["KILLED_REASON", "META_PERIOD", "StreamSession", "StreamSettings", "load_plan",
           "open_session", "plan_box"]

#: The reason meta.json gives while the flight runs: what a reader sees after a kill -9.
KILLED_REASON = ("the streamer stopped without its final write (killed or crashed); "
                 "samples as of 'updated'")
#: Streamer seconds between the live rewrites of meta.json.
META_PERIOD = 1.0


@dataclass(frozen=True)
class StreamSettings:
    """How to fly a trajectory file (times in streamer seconds, see `LinkClock`).

    Attributes
    ----------
    connect : str
        The MAVLink connection (see `MavlinkLink`).
    rate : float
        Setpoints per second, Hz.
    telemetry_rate : float
        Rate asked for the estimator's telemetry, Hz.
    land : bool
        Land after the trajectory (else keep hovering at its end).
    box : tuple of 6 float or None
        The operator's flight box [x_min, y_min, z_min, x_max, y_max, z_max], m; None: the
        ``[flight] box`` of the vehicle file given (nothing flies without one).
    signing_key : bytes or None
        MAVLink 2 signing key.
    speedup : float
        Streamer seconds per wall second (a faster-than-real-time simulator).
    heartbeat_timeout : float
        How long to wait for the vehicle's first heartbeat, wall s (not sped up).
    heartbeat_loss : float
        The vehicle is lost after this long without a heartbeat, s.
    position_timeout : float
        How long to wait for a usable local position, s.
    max_tracking_error : float
        Abort to hold beyond this distance from the setpoint in effect, m (reported from
        half of it).
    max_motor_imbalance : float
        Abort when a motor is asked for this many times the thrust of its mirror
        (`mavsysid.flight.ground.motor_watch`).
    log_dir : Path
        Root of the flight directories.
    hold_time : float
        Hover at the end of the trajectory before landing, s.
    transfer_speed : float
        Top speed of the moves to the start, m/s.
    settle_tolerance, settle_time, settle_timeout : float
        Settled at the start: within the tolerance (m) and below 0.1 m/s for settle_time
        (s); give up waiting after settle_timeout (s).
    land_timeout : float
        Give up waiting for the landing after this long with the vehicle coming no lower
        (or, on the ground, not disarming), s (`mavsysid.flight.ground.landing`).
    link_loss : float
        The vehicle is lost after this long without any message once its telemetry
        streams, s (`mavsysid.flight.ground.link_state`).
    prearm_timeout : float
        How long to wait for the vehicle's pre-arm checks to pass, s.
    realtime : bool
        Run the flight's threads with real-time scheduling when permitted
        (`mavsysid.flight.ground.realtime`).
    fence, fence_margin : bool, float or None
        Geofence before arming, this far outside the box, m (None: `geofence.FENCE_MARGIN`).
    set_limits : bool
        Raise the autopilot limits the plan needs (`autopilot_limits`), not refuse.
    lockstep : bool
        Take the time from ``mavsysid sim --lockstep``'s frames (`LinkClock`; tests).
    dry_run : bool
        Connect and run every check, list the box, the fence and the parameters the flight
        would change, and stop there: nothing armed, no parameter written, no fence
        uploaded.
    download_log : bool
        After a completed flight that landed, download the vehicle's own log of it
        (`mavsysid.flight.ground.log_download`) into the flight directory.
    """

    connect: str
    rate: float = 50.0
    telemetry_rate: float = 50.0
    land: bool = True
    box: tuple[float, ...] | None = None
    signing_key: bytes | None = field(default=None, repr=False)
    speedup: float = 1.0
    heartbeat_timeout: float = 30.0
    heartbeat_loss: float = 3.0
    position_timeout: float = 90.0
    max_tracking_error: float = 1.0
    max_motor_imbalance: float = 2.0
    log_dir: Path = Path("logs")
    hold_time: float = 2.0
    transfer_speed: float = 1.0
    settle_tolerance: float = 0.05
    settle_time: float = 1.0
    settle_timeout: float = 15.0
    land_timeout: float = 60.0
    link_loss: float = 1.0
    prearm_timeout: float = 60.0
    realtime: bool = True
    fence: bool = True
    fence_margin: float | None = None
    set_limits: bool = False
    lockstep: bool = False
    dry_run: bool = False
    download_log: bool = False


def _embedded_config(plan: TrajectoryFile, source: str) -> VehicleConfig:
    """The vehicle configuration stored in a trajectory file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{plan.vehicle_name or 'vehicle'}.toml"
        path.write_text(plan.vehicle_toml, encoding="utf-8")
        config = load_vehicle(path)
    # The temporary path means nothing to a reader of the metadata.
    return replace(config, source=f"{source} (embedded)")


def load_plan(path: str | Path, vehicle: str | Path | None,
              box: tuple[float, ...] | None) -> tuple[TrajectoryFile, VehicleConfig,
                                                      tuple[float, ...]]:
    """Read a trajectory file, its vehicle and box, and refuse a plan that cannot fly.

    Parameters
    ----------
    path : str or Path
        The trajectory file.
    vehicle : str, Path or None
        Shipped vehicle name or TOML path; None: the configuration stored in the file.
    box : tuple of 6 float or None
        The operator's flight box, m; None: the ``[flight] box`` of ``vehicle`` (never of
        the configuration stored in the file). The file's own box only narrows it.

    Returns
    -------
    plan, config, box
        The file, the vehicle and the box in use (see `plan_box` for where it came from).

    Raises
    ------
    InputError
        An unreadable file or vehicle, or no box from the operator.
    JobFailedError
        "flight refused: …": another vehicle's trajectory, a sample outside the box, or
        the vehicle's limits exceeded (`mavsysid.flight.ground.trajectory_safety`).
    """
    plan, config, box, _source = plan_box(path, vehicle, box)
    return plan, config, box


def plan_box(path: str | Path, vehicle: str | Path | None, box: tuple[float, ...] | None
             ) -> tuple[TrajectoryFile, VehicleConfig, tuple[float, ...], str]:
    """`load_plan` and where the box came from (``--box``, the vehicle's, narrowed…).

    Parameters
    ----------
    path : str or Path
        The trajectory file.
    vehicle : str, Path or None
        Shipped vehicle name or TOML path; None: the configuration stored in the file.
    box : tuple of 6 float or None
        The operator's flight box, [x_min, y_min, z_min, x_max, y_max, z_max], m, world
        ENU; None: the ``[flight] box`` of ``vehicle``. The file's own box only narrows it.

    Returns
    -------
    plan, config, box
        As `load_plan`.
    source : str
        Where the box came from, for messages and ``meta.json`` (`operator_box`).
    """
    plan = read_trajectory(path)
    config = load_vehicle(vehicle) if vehicle is not None else _embedded_config(plan, str(path))
    # The operator's box (--box, else the chosen vehicle file's); the file's only narrows it.
    box, source = operator_box(box, None if vehicle is None else config.box, plan.box,
                               str(path))
    check_plan(plan.trajectory, plan.vehicle_name, config, box, source).raise_if_refused()
    return plan, config, tuple(float(b) for b in box), source


class StreamSession:
    """The resources and records of one streamed flight (see the module docstring).

    Attributes
    ----------
    plan, config, box, settings, directory
        What is flown, by which vehicle, where, how, and where it is recorded.
    box_source : str
        Where the box came from (``--box``, the vehicle's ``[flight] box``, narrowed…).
    trajectory : PiecewisePolynomial
    link, commands, history, recorder, stream, guards
        The flight's machinery, wired together.
    last_sys_status : message or None
    """

    def __init__(self, path: Path, plan: TrajectoryFile, config: VehicleConfig,
                 box: tuple[float, ...], settings: StreamSettings,
                 box_source: str = "--box") -> None:
        self.plan, self.config, self.box, self.settings = plan, config, box, settings
        self.box_source = box_source
        self.trajectory = plan.trajectory
        self._made_root = not Path(settings.log_dir).exists()
        self.directory = stream_flight_dir(Path(settings.log_dir), Path(path).stem)
        self.history = SetpointHistory()
        # The streamer says whether the vehicle sends its IMU, once the telemetry streams.
        self.recorder = TelemetryRecorder(self.directory / "pose.csv", config, self.history,
                                          imu=None)
        self.meta: dict[str, Any] = self._initial_meta(path)
        self._outcome: tuple[str, str | None] | None = None
        # Before any thread starts: they inherit the policy (see realtime's docstring).
        self.meta["stream"]["scheduling"] = raise_priority() if settings.realtime else "normal"
        self._meta_writer = MetaWriter(self.directory / "meta.json")
        self._next_meta = 0.0
        self._write()
        clock = LinkClock(settings.speedup, settings.lockstep)
        self.meta["tlog_epoch_unix_s"] = clock.epoch_us(0.0) * 1e-6
        try:
            # Spin the last 2 ms before each setpoint (at most a tenth of the period).
            spin = min(0.002, 0.1 / (settings.rate * settings.speedup))
            self.link = MavlinkLink(settings.connect, self.directory / "flight.tlog", clock,
                                    settings.signing_key, settings.heartbeat_loss, spin,
                                    settings.link_loss)
        except BaseException as error:
            self.recorder.close()
            self.note_failure(str(error))
            self._write_final()
            restore_scheduling()
            self._forget_unanswered()
            raise
        self.commands = VehicleCommands(self.link, say=None)
        # Restored by the streamer; a dry run only lists what it would set.
        self.parameters = ParameterSession(self.link, dry_run=settings.dry_run)
        self.stream = SetpointStream(self.link, self.history, settings.rate)
        self.stream.limits = flight_limits(config, box)
        self.guards = FlightGuards(self.link, self.stream, self.recorder)
        self.prearm = PrearmMonitor(self.link)
        self.last_sys_status: Any = None
        # Order matters: the guards read the row the recorder has just written.
        self.link.add_listener(self.recorder.on_message)
        self.link.add_listener(self._on_message)
        self.link.add_listener(self.prearm.on_message)
        self.link.add_listener(self.guards.on_message)
        self._trajectory_start: float | None = None
        self._old_handlers: dict[int, Any] = {}

    def _on_message(self, msg: Any, t: float) -> None:
        if msg.get_type() == "SYS_STATUS":
            self.last_sys_status = msg
        if t >= self._next_meta:  # the live meta.json, about once a second
            self._write()

    # --- metadata --------------------------------------------------------------------------

    def _initial_meta(self, path: Path) -> dict[str, Any]:
        s, plan = self.settings, self.plan
        return {
            "format": "mavsysid-flight", "format_version": 1,
            "software": {"name": "mavsysid", "version": software_version()},
            "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "source": STREAM_SOURCE, "simulated": False,
            "vehicle": {"name": self.config.name, "source": self.config.source,
                        "config_toml": vehicle_to_toml(self.config)},
            "files": {"pose": "pose.csv", "tlog": "flight.tlog"},
            "connection": s.connect, "speedup": s.speedup,
            "lockstep": s.lockstep, "dry_run": s.dry_run,
            "signing": s.signing_key is not None,
            "trajectory": {"file": str(path), "kind": plan.kind,
                           "duration": self.trajectory.duration,
                           "vehicle": plan.vehicle_name, "box": list(self.box),
                           "box_source": self.box_source,
                           "start": list(plan.start), "predicted_dopt": plan.predicted_dopt},
            "stream": {"setpoint_rate_hz": s.rate, "telemetry_rate_hz": s.telemetry_rate,
                       "max_tracking_error_m": s.max_tracking_error,
                       "max_motor_imbalance": s.max_motor_imbalance, "land": s.land,
                       "type_mask": 0, "frame": "MAV_FRAME_LOCAL_NED"},
            "stamping": STAMPING,
            "tlog_time": "tlog_epoch_unix_s + streamer time (wall time x speedup since the "
                         "streamer started), us",
            "status": "aborted",
            "reason": KILLED_REASON,
            "running": True,
            "samples": 0,
        }

    def _write(self) -> None:
        """Queue a live rewrite of meta.json (off this thread)."""
        self.meta["samples"] = self.recorder.rows
        self.meta["updated"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")
        self._meta_writer.submit(self.meta)
        link = getattr(self, "link", None)
        self._next_meta = (0.0 if link is None else link.clock.now()) + META_PERIOD

    @property
    def type_name(self) -> str:
        """The vehicle's MAV_TYPE without its prefix (e.g. ``HEXAROTOR``)."""
        return self.link.enum_name("MAV_TYPE", self.link.vehicle.mav_type).removeprefix(
            "MAV_TYPE_")

    @property
    def sensor_names(self) -> dict[int, str]:
        """MAV_SYS_STATUS_SENSOR bit → name."""
        return {k: e.name for k, e in self.link.mavlink.enums["MAV_SYS_STATUS_SENSOR"].items()}

    def note_vehicle(self) -> None:
        """Record the vehicle's identity from its heartbeat."""
        v = self.link.vehicle
        self.meta["autopilot"] = {
            "family": None if v.autopilot is None else v.autopilot.name.lower(),
            "autopilot": self.link.enum_name("MAV_AUTOPILOT", v.autopilot_id),
            "type": self.type_name, "system": v.system, "component": v.component}
        self._write()

    def note_rates(self, achieved: dict[str, float]) -> None:
        """Record the telemetry rates measured before the flight, Hz."""
        self.meta["telemetry_rates_hz"] = {"requested": self.settings.telemetry_rate,
                                           "preflight": dict(sorted(achieved.items()))}
        self._write()

    def vehicle_time(self, t: float) -> float | None:
        """Streamer time ``t`` on pose.csv's clock (the vehicle's), s; None before known."""
        offset = self.recorder.offset.value
        return None if offset is None else t - offset

    def note_trajectory_start(self, t: float) -> None:
        """The trajectory's first setpoint went out at streamer time ``t``."""
        self._trajectory_start = t
        self.meta["trajectory_window"] = {
            "start": self.vehicle_time(t), "end": None,
            "clock": "pose.csv t (vehicle time_boot_ms), s",
            "streamer_start": t, "streamer_end": None}
        self._write()

    def note_trajectory_end(self, t: float, statistics: dict[str, Any]) -> None:
        """The trajectory ended (or was cut) at streamer time ``t``; its setpoint stats."""
        window = self.meta.setdefault("trajectory_window", {})
        window["end"], window["streamer_end"] = self.vehicle_time(t), t
        self.meta["setpoints"] = {**statistics, "clock": "streamer time (wall x speedup)"}
        self._write()

    def note_failure(self, reason: str) -> None:
        """The flight failed, was refused or interrupted: final status ``aborted``, ``reason``."""
        if self._outcome is None:
            self._outcome = ("aborted", reason)

    def note(self, key: str, value: Any) -> None:
        """Record ``value`` under ``key`` in meta.json now (the fence, changed parameters)."""
        self.meta[key] = value
        self._write()

    def note_complete(self) -> None:
        """The flight went as planned (final status ``complete``)."""
        if self._outcome is None:
            self._outcome = ("complete", None)

    def _write_final(self) -> None:
        status, reason = self._outcome or ("aborted", "stopped before the end")
        self.meta["status"], self.meta["running"] = status, False
        if reason is None:
            self.meta.pop("reason", None)
        else:
            self.meta["reason"] = reason
        self.meta["tracking"] = self.recorder.tracking_summary()
        if self.recorder.writes_imu:
            self.meta.setdefault("imu", {}).update(self.recorder.imu_summary())
        self.meta.setdefault("telemetry_rates_hz", {})["flight"] = {
            k: round(v, 3) for k, v in sorted(self.recorder.rates().items())}
        if self.recorder.skipped:
            self.meta["rows_skipped"] = dict(self.recorder.skipped)
        link = getattr(self, "link", None)
        if link is not None and (link.rejected_signed or link.rejected_unsigned):
            self.meta["signing_rejects"] = {"wrong_signature": link.rejected_signed,
                                            "unsigned": link.rejected_unsigned}
        self.meta["samples"] = self.recorder.rows
        self.meta["updated"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")
        self._meta_writer.close(final=self.meta)

    # --- lifetime --------------------------------------------------------------------------

    def _on_signal(self, _signum: int, _frame: Any) -> None:
        if self.link.interrupt_pending:
            raise KeyboardInterrupt
        self.link.interrupt_pending = True

    def __enter__(self) -> StreamSession:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old_handlers[sig] = signal.signal(sig, self._on_signal)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._old_handlers.items():
            signal.signal(sig, handler)
        self.close()

    def close(self) -> None:
        """Stop streaming, close the link and the logs, write the final meta.json."""
        self.stream.stop()
        self.link.close()
        self.recorder.close()
        try:
            self._write_final()
        finally:
            restore_scheduling()
            self._forget_unanswered()

    def _forget_unanswered(self) -> None:
        """No vehicle ever answered: remove the flight directory (and the log root made
        for it, when empty), so failed connections leave nothing behind."""
        link = getattr(self, "link", None)
        if link is not None and link.vehicle.heartbeats > 0:
            return
        shutil.rmtree(self.directory, ignore_errors=True)
        if self._made_root:
            with contextlib.suppress(OSError):
                Path(self.settings.log_dir).rmdir()


def open_session(path: str | Path, settings: StreamSettings,
                 vehicle: str | Path | None = None) -> StreamSession:
    """Check the plan, then create the flight directory and connect (see `load_plan`)."""
    parse_connect(settings.connect)  # bad input creates no flight directory
    plan, config, box, source = plan_box(path, vehicle, settings.box)
    return StreamSession(Path(path), plan, config, box, settings, source)
