"""The simulated vehicle's own flight log and the MAVLink log protocol that serves it.

`OnboardLog` records what the autopilot would log while armed (ArduPilot's LOG_DISARMED
0, the default; PX4's SDLOG_MODE 0): at every tick the published pose, world velocity,
ESC rotor speeds, commanded rotor speeds, the IMU's reading and the mode. Each armed
period is one log, numbered from 1. A log is built when its armed period ends, in a
thread of its own so that the vehicle's ticks go on, as ArduPilot writes it
(`mavsysid.flight.offline.ardupilot_log`, a DataFlash ``.bin``: IMU at the loop rate when
LOG_BITMASK has IMU_FAST, else 25 Hz) or PX4 (`mavsysid.flight.offline.px4_log`, a
``.ulg``), in the vehicle's autopilot motor numbering when its file names the frame.

`LogService` answers the log protocol as ArduPilot's ``GCS_MAVLINK::handle_log_*`` do
(MAVLink common, "Log download"):

- LOG_REQUEST_LIST (start, end) → a LOG_ENTRY (id, num_logs, last_log_num, time_utc,
  size) per log in [start, end] (end 0xFFFF: the last), once the logs are built; none
  while armed;
- LOG_REQUEST_DATA (id, ofs, count) → LOG_DATA (id, ofs, count, 90 data bytes) for the
  range, `DATA_PER_TICK` messages per 2 ms tick; a range at or past the end gets one
  LOG_DATA of count 0; a new request replaces the one being sent;
- LOG_REQUEST_END stops the transfer; LOG_ERASE forgets the logs.
"""

from __future__ import annotations

import tempfile
import threading
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.flight.autopilot_modes import Autopilot, mode_name
from mavsysid.flight.offline.ardupilot_log import ArduPilotLogSettings, write_ardupilot_log
from mavsysid.flight.offline.autopilot_log import LoggedFlight
from mavsysid.flight.offline.px4_log import PX4LogSettings, write_px4_log
from mavsysid.flight.simvehicle.link import mavlink
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.motor_order import output_to_rotor

__all__ = ["DATA_PER_TICK", "LOG_DATA_BYTES", "LogService", "OnboardLog"]

M = mavlink
#: Data bytes of one LOG_DATA message.
LOG_DATA_BYTES = 90
#: LOG_DATA messages sent per tick (500 ticks a second of sim time): 45 kB/s × 4.
DATA_PER_TICK = 4
#: LOG_BITMASK bit of ArduCopter's IMU_FAST (MASK_LOG_IMU_FAST): IMU at the loop rate.
_IMU_FAST = 1 << 18
_LAST_LOG = 0xFFFF


@dataclass
class _Recording:
    """One armed period's samples, appended tick by tick."""

    t: list[float] = field(default_factory=list)
    rows: list[np.ndarray] = field(default_factory=list)
    modes: list[tuple[float, str]] = field(default_factory=list)
    data: bytes | None = None
    built: threading.Event = field(default_factory=threading.Event)


class OnboardLog:
    """The vehicle's flight logs (see the module docstring).

    Parameters
    ----------
    config : VehicleConfig
        The vehicle: its rotors (motor numbering) and motor curve (RCOU PWM).
    autopilot : Autopilot
        Which autopilot's log to write.
    parameter : callable
        ``name → value or None``: the autopilot's parameters (LOG_BITMASK).
    """

    def __init__(self, config: VehicleConfig, autopilot: Autopilot,
                 parameter: Callable[[str], float | None]) -> None:
        self.config, self.autopilot, self.parameter = config, autopilot, parameter
        self.logs: list[_Recording] = []
        self._current: _Recording | None = None
        self._lock = threading.Lock()

    def record(self, t: float, armed: bool, mode: int, vehicle: Any) -> None:
        """One tick: a sample while armed; arming starts a log, disarming builds it.

        Parameters
        ----------
        t : float
            Sim time, s.
        armed : bool
            Whether the vehicle is armed this tick.
        mode : int
            Its custom_mode.
        vehicle : SimVehicle
            What it publishes (pose, rotor speeds, IMU) and commands.
        """
        if not armed:
            if self._current is not None:
                threading.Thread(target=self.data, args=(self._current,), name="onboard-log",
                                 daemon=True).start()
            self._current = None
            return
        if self._current is None:
            self._current = _Recording()
            self.logs.append(self._current)
        log = self._current
        name = mode_name(self.autopilot, mode)
        if not log.modes or log.modes[-1][1] != name:
            log.modes.append((t, name))
        position, quaternion, speeds = vehicle.measured()
        gyro, accel = vehicle.imu_measured()
        log.t.append(t)
        log.rows.append(np.concatenate([position, quaternion, vehicle.velocity(), speeds,
                                        vehicle.n_cmd, gyro, accel]))

    def finished(self) -> list[_Recording]:
        """The logs whose armed period has ended."""
        return [log for log in self.logs if log is not self._current]

    def data(self, log: _Recording) -> bytes:
        """The log's file, built on first use (by one thread; others wait for it).

        Parameters
        ----------
        log : _Recording
            One of `logs`.
        """
        with self._lock:
            if log.data is None:
                with tempfile.TemporaryDirectory() as tmp:
                    path = Path(tmp) / "log"
                    self._write(path, log)
                    log.data = path.read_bytes()
                log.built.set()
        return log.data

    def ready(self) -> bool:
        """Whether every finished log is built."""
        return all(log.built.is_set() for log in self.finished())

    def _write(self, path: Path, log: _Recording) -> None:
        cfg, k = self.config, self.config.rotor_count
        rows = np.array(log.rows)
        t = np.array(log.t)
        flight = LoggedFlight(t - t[0], rows[:, 0:3], rows[:, 3:7], rows[:, 7:10],
                              rows[:, 10:10 + k], rows[:, 10 + k:10 + 2 * k], None,
                              rows[:, 10 + 2 * k:13 + 2 * k], rows[:, 13 + 2 * k:16 + 2 * k],
                              cfg.imu_position,
                              tuple((tm - t[0], name) for tm, name in log.modes))
        order = (list(range(k)) if cfg.autopilot_frame is None else
                 output_to_rotor(cfg.rotor_positions, cfg.rotor_directions,
                                 cfg.autopilot_frame))
        if self.autopilot is Autopilot.ARDUPILOT:
            mask = int(self.parameter("LOG_BITMASK") or 0)
            settings = ArduPilotLogSettings(imu_rate=400.0 if mask & _IMU_FAST else 25.0,
                                            boot_time=float(t[0]))
            write_ardupilot_log(path, flight, cfg, order, settings)
        else:
            write_px4_log(path, flight, cfg.limits.rotor_speed_max, order,
                          PX4LogSettings(boot_time=float(t[0])))


class LogService:
    """The log protocol over the simulated link (see the module docstring).

    Parameters
    ----------
    logs : OnboardLog
    armed : callable
        ``() → bool``: whether the vehicle is armed now.
    """

    def __init__(self, logs: OnboardLog, armed: Callable[[], bool]) -> None:
        self.logs, self.armed = logs, armed
        self._sending: deque[tuple[int, bytes, int]] = deque()  # (id, data, offset)
        self._end = 0
        self._listing: Any = None  # a LOG_REQUEST_LIST waiting for the logs to be built

    def handle(self, msg: Any) -> list[Any]:
        """The immediate replies to one LOG_* message.

        Parameters
        ----------
        msg : pymavlink message
            LOG_REQUEST_LIST, LOG_REQUEST_DATA, LOG_REQUEST_END or LOG_ERASE.
        """
        kind = msg.get_type()
        finished = self.logs.finished()
        if kind == "LOG_REQUEST_LIST":
            if self.armed() or not finished:
                return [] if self.armed() else [M.MAVLink_log_entry_message(0, 0, 0, 0, 0)]
            if not self.logs.ready():
                self._listing = msg
                return []
            last = len(finished) if msg.end == _LAST_LOG else min(msg.end, len(finished))
            return [M.MAVLink_log_entry_message(i, len(finished), len(finished), 0,
                                                len(self.logs.data(finished[i - 1])))
                    for i in range(max(1, msg.start), last + 1)]
        if kind == "LOG_REQUEST_DATA":
            self._sending.clear()
            if self.armed() or not 1 <= msg.id <= len(finished):
                return []
            data = self.logs.data(finished[msg.id - 1])
            if msg.ofs >= len(data):
                return [M.MAVLink_log_data_message(msg.id, msg.ofs, 0, [0] * LOG_DATA_BYTES)]
            self._end = min(len(data), msg.ofs + msg.count)
            self._sending.append((msg.id, data, msg.ofs))
            return []
        if kind in ("LOG_REQUEST_END", "LOG_ERASE"):
            self._sending.clear()
            if kind == "LOG_ERASE":
                self.logs.logs = [log for log in self.logs.logs if log not in finished]
        return []

    def due(self) -> Iterator[Any]:
        """The LOG_DATA messages of this tick (or the LOG_ENTRYs of a waiting list)."""
        if self._listing is not None and self.logs.ready():
            listing, self._listing = self._listing, None
            yield from self.handle(listing)
        for _ in range(DATA_PER_TICK):
            if not self._sending:
                return
            log_id, data, ofs = self._sending.popleft()
            chunk = data[ofs:min(ofs + LOG_DATA_BYTES, self._end)]
            yield M.MAVLink_log_data_message(log_id, ofs, len(chunk),
                                             list(chunk.ljust(LOG_DATA_BYTES, b"\0")))
            if ofs + len(chunk) < self._end:
                self._sending.append((log_id, data, ofs + len(chunk)))
