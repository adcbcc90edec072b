"""The pose log of a streamed flight, from the vehicle's telemetry as it arrives.

One row of ``pose.csv`` per LOCAL_POSITION_NED, stamped with its ``time_boot_ms`` (the
vehicle's clock), carrying:

- the position (NED → ENU) and velocity (``vx, vy, vz``, ENU);
- the latest attitude received before it: ATTITUDE_QUATERNION (q_ned_frd → q_enu_flu),
  or ATTITUDE's Euler angles until a quaternion has arrived;
- the latest ESC rpm received before it (ESC_TELEMETRY_1_TO_4 / _5_TO_8, rpm → rad/s),
  ESC i as the rotor motor output i drives (the vehicle file's ``[autopilot] frame``;
  without one ESC i is rotor i). ESC telemetry carries no timestamp, and an autopilot
  sends it in the same tick just before the LOCAL_POSITION_NED, so it takes that row's
  stamp;
- with the IMU (``imu``), the latest IMU sample received before it (RAW_IMU, HIGHRES_IMU
  or SCALED_IMU, `mavsysid.flight.ground.imu_telemetry`) in the IMU columns, body FLU;
  the samples between rows are in ``flight.tlog``. Whether the vehicle sends its IMU is
  known only once the telemetry streams: until `use_imu` says so, rows are held in
  memory (the ground rows before take-off), then written;
- the target in effect at the vehicle at that time (``x_ref, y_ref, z_ref, yaw_ref``
  ENU, ``ref_active`` 1/0, ``t_traj`` its trajectory time or −1): the last setpoint
  sent before the row's time mapped onto the streamer's clock, advanced from the time
  it was sampled to the row's time along its own velocity and acceleration, as the
  autopilot does between setpoints (`Setpoint.advanced`). The map is receipt time minus
  ``time_boot_ms``, minimised over a sliding window of a few seconds (the fastest
  message has the least latency); the setpoint's own uplink latency is neglected. Rows
  without a setpoint in effect repeat the measured pose with ``ref_active`` 0.

Every row reaches the OS as it is written (`PoseLogWriter`), so a killed streamer keeps
the log up to its last message.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.flight.ground.imu_telemetry import ImuTelemetry
from mavsysid.flight.ground.setpoints import Setpoint
from mavsysid.formats.poselog import PoseLogWriter
from mavsysid.formats.tlog import ESC_TELEMETRY
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import euler_ned_to_quaternion, ned_to_enu, quaternion_ned_to_enu
from mavsysid.vehicle.motor_order import output_order
from mavsysid.vehicle.rotation import quat_yaw

__all__ = [
    "EXTRA_COLUMNS",
    "STAMPING",
    "ClockOffset",
    "PoseSample",
    "SetpointHistory",
    "TelemetryRecorder",
]

EXTRA_COLUMNS = ("vx", "vy", "vz", "x_ref", "y_ref", "z_ref", "yaw_ref", "ref_active",
                 "t_traj")
_CLOCKED = ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "ATTITUDE")

#: How each column group of pose.csv is stamped (stored in meta.json).
STAMPING = {
    "t": "LOCAL_POSITION_NED.time_boot_ms (the vehicle's clock), s",
    "pose": "one row per LOCAL_POSITION_NED; attitude: the latest ATTITUDE_QUATERNION "
            "received before it (ATTITUDE Euler angles until the first quaternion)",
    "rotor_speeds": "ESC_TELEMETRY_* carries no timestamp: each row holds the latest ESC "
                    "rpm received before its LOCAL_POSITION_NED, i.e. ESC telemetry is "
                    "stamped with the LOCAL_POSITION_NED that follows it (sent in the same "
                    "autopilot tick); rpm x 2 pi / 60 = rad/s; 0 before the first ESC message",
    "reference": "the last setpoint sent before the row's time mapped to the streamer's "
                 "clock (offset = min over a sliding window of receipt time - time_boot_ms; "
                 "uplink latency neglected), advanced from its sample time to the row's "
                 "time with its own velocity and acceleration (p + v dt + a dt^2/2, as the "
                 "autopilot extrapolates); ref_active 0 and the measured pose when none "
                 "was in effect; t_traj = trajectory time of that target, -1 outside",
    "imu": "the latest RAW_IMU (ArduPilot, mG and mrad/s), HIGHRES_IMU or SCALED_IMU "
           "received before the row's LOCAL_POSITION_NED, FRD -> FLU; its own time_usec / "
           "time_boot_ms is not the row's (meta.json imu.lag_s: row time minus IMU time)",
}


class ClockOffset:
    """Streamer time minus vehicle time, from receipt stamps: a sliding-window minimum.

    Parameters
    ----------
    window : float
        The minimum is over the last one to two windows, streamer s, so that it follows a
        vehicle clock that runs a little slower or faster than ours.
    """

    def __init__(self, window: float = 5.0) -> None:
        self.window = window
        self._current = self._previous = math.inf
        self._bucket_end: float | None = None

    def add(self, t_receipt: float, t_vehicle: float) -> None:
        """One message received at ``t_receipt`` (streamer s) stamped ``t_vehicle`` (s)."""
        if self._bucket_end is None:
            self._bucket_end = t_receipt + self.window
        while t_receipt >= self._bucket_end:
            self._previous, self._current = self._current, math.inf
            self._bucket_end += self.window
        self._current = min(self._current, t_receipt - t_vehicle)

    @property
    def value(self) -> float | None:
        """The offset, s (None before the first message)."""
        v = min(self._current, self._previous)
        return None if math.isinf(v) else v


class SetpointHistory:
    """The setpoints sent recently: send time, sample time (streamer s), setpoint.

    A None setpoint marks a stop. The sample time is the schedule time the setpoint was
    evaluated for (its send time minus the stream's jitter).
    """

    def __init__(self, keep: float = 10.0) -> None:
        self.keep = keep
        self._entries: deque[tuple[float, float, Setpoint | None]] = deque()

    def add(self, t: float, setpoint: Setpoint | None, sampled: float | None = None) -> None:
        """Record ``setpoint`` sent at ``t``, evaluated for ``sampled`` (default ``t``)."""
        self._entries.append((t, t if sampled is None else sampled, setpoint))
        while self._entries and self._entries[0][0] < t - self.keep:
            self._entries.popleft()

    def at(self, t: float) -> Setpoint | None:
        """The target at streamer time ``t``: the last setpoint sent at or before ``t``,
        advanced from its sample time to ``t`` (`Setpoint.advanced`); None if none."""
        for sent, sampled, setpoint in reversed(self._entries):
            if sent <= t:
                return None if setpoint is None else setpoint.advanced(t - sampled)
        return None

    @property
    def last(self) -> Setpoint | None:
        """The last setpoint sent (None if none, or streaming stopped)."""
        return self._entries[-1][2] if self._entries else None


@dataclass(frozen=True)
class PoseSample:
    """The latest pose row: t (vehicle s), position and velocity (ENU), yaw (ENU, rad),
    tracking error (m, None without a setpoint in effect) and that setpoint."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    tracking_error: float | None
    reference: Setpoint | None


class TelemetryRecorder:
    """Writes ``pose.csv`` from the vehicle's messages (see the module docstring).

    Parameters
    ----------
    path : Path
        The pose log to create.
    config : VehicleConfig
        The vehicle: its rotor count k.
    history : SetpointHistory
        The setpoints sent, for the reference columns.
    imu : bool or None
        Write the IMU columns (True), not (False), or decide later (None: rows are held
        until `use_imu`).

    Use `on_message` as a `MavlinkLink` listener.
    """

    def __init__(self, path: Path, config: VehicleConfig, history: SetpointHistory,
                 imu: bool | None = False) -> None:
        self.config = config
        self.history = history
        self.offset = ClockOffset()
        self.counts: Counter[str] = Counter()
        self.first_seen: dict[str, float] = {}
        self.last_seen: dict[str, float] = {}
        self.latest: PoseSample | None = None
        self.skipped: Counter[str] = Counter()
        self._k = config.rotor_count
        self._rotors = np.zeros(self._k)
        self._outputs = output_order(config.rotor_positions, config.rotor_directions,
                                     config.autopilot_frame)
        self._esc_seen = False
        self._quaternion: np.ndarray | None = None  # ENU/FLU
        self._has_att_q = False
        self._last_t = -math.inf
        self._track_sq, self._track_n, self._track_max = 0.0, 0, 0.0
        self.imu = ImuTelemetry()
        self._path = path
        self._writer: PoseLogWriter | None = None
        self._held: list[tuple[Any, ...]] = []
        self._lags: list[float] = []
        if imu is not None:
            self.use_imu(imu)

    @property
    def rows(self) -> int:
        """Rows written so far."""
        return 0 if self._writer is None else self._writer.rows_written

    @property
    def writes_imu(self) -> bool | None:
        """Whether the rows carry the IMU (None: not decided yet)."""
        return None if self._writer is None else self._writer.imu

    def use_imu(self, enabled: bool) -> None:
        """Decide whether the rows carry the IMU; write the rows held until now (those
        before the first IMU sample are left out with the IMU). Once only.

        Parameters
        ----------
        enabled : bool
            The vehicle sends its IMU: the rows carry it.
        """
        if self._writer is not None:
            return
        self._writer = PoseLogWriter(self._path, self._k, EXTRA_COLUMNS, imu=enabled)
        held, self._held = self._held, []
        for row in held:
            self._write(*row)

    def imu_summary(self) -> dict[str, Any]:
        """The IMU in the rows: message, samples received, row time minus IMU time (s)."""
        latest = self.imu.latest
        lags = np.array(self._lags) if self._lags else np.zeros(1)
        return {"message": None if latest is None else latest.message,
                "samples_received": self.imu.count, "rows": len(self._lags),
                "lag_s": {"mean": float(lags.mean()), "max": float(lags.max())}}

    def on_message(self, msg: Any, t_receipt: float) -> None:
        """Handle one message from the vehicle received at ``t_receipt`` (streamer s)."""
        kind = msg.get_type()
        self.counts[kind] += 1
        self.first_seen.setdefault(kind, t_receipt)
        self.last_seen[kind] = t_receipt
        if kind in _CLOCKED:
            self.offset.add(t_receipt, msg.time_boot_ms * 1e-3)
        if self.imu.on_message(msg):
            return
        if kind == "LOCAL_POSITION_NED":
            self._row(msg)
        elif kind == "ATTITUDE_QUATERNION":
            q = np.array([msg.q1, msg.q2, msg.q3, msg.q4], dtype=float)
            norm = float(np.linalg.norm(q))
            if norm > 0.5:
                self._quaternion = quaternion_ned_to_enu(q / norm)
                self._has_att_q = True
        elif kind == "ATTITUDE" and not self._has_att_q:
            self._quaternion = quaternion_ned_to_enu(
                euler_ned_to_quaternion(msg.roll, msg.pitch, msg.yaw))
        elif kind in ESC_TELEMETRY:
            base = ESC_TELEMETRY[kind]
            for j in range(min(4, self._k - base)):
                self._rotors[self._outputs[base + j]] = msg.rpm[j] * RPM_TO_RAD_S
            self._esc_seen = self._esc_seen or base < self._k

    def _row(self, msg: Any) -> None:
        t = msg.time_boot_ms * 1e-3
        if self._quaternion is None:
            self.skipped["no attitude yet"] += 1
            return
        if round(t, 6) <= self._last_t:
            self.skipped["time not increasing"] += 1
            return
        position = ned_to_enu(np.array([msg.x, msg.y, msg.z], dtype=float))
        velocity = ned_to_enu(np.array([msg.vx, msg.vy, msg.vz], dtype=float))
        q = self._quaternion
        yaw = float(quat_yaw(np.asarray(q, dtype=float)))
        offset = self.offset.value
        ref = self.history.at(t + offset) if offset is not None else None
        if ref is None:
            ref_values, error = (*position, yaw, 0.0, -1.0), None
        else:
            ref_values = (*ref.position, ref.yaw, 1.0, ref.t_traj)
            error = float(np.linalg.norm(position - np.asarray(ref.position)))
            if ref.t_traj >= 0.0:
                self._track_sq += error * error
                self._track_n += 1
                self._track_max = max(self._track_max, error)
        extra = dict(zip(EXTRA_COLUMNS, (*velocity, *ref_values), strict=True))
        row = (t, position, q / np.linalg.norm(q), self._rotors.copy(), extra, self.imu.latest)
        if self._writer is None:
            self._held.append(row)
        else:
            self._write(*row)
        self._last_t = round(t, 6)
        self.latest = PoseSample(t, position, velocity, yaw, error, ref)

    def _write(self, t: float, position: np.ndarray, q: np.ndarray, rotors: np.ndarray,
               extra: dict[str, float], imu: Any) -> None:
        assert self._writer is not None
        if not self._writer.imu:
            self._writer.write(t, position, q, rotors, extra)
            return
        if imu is None:
            self.skipped["before the first IMU sample"] += 1
            return
        self._writer.write(t, position, q, rotors, extra, gyro=imu.gyro, accel=imu.accel)
        self._lags.append(t - imu.t)

    def rates(self) -> dict[str, float]:
        """Achieved rate of each message type so far, Hz, from receipt times."""
        out = {}
        for kind, n in self.counts.items():
            span = self.last_seen[kind] - self.first_seen[kind]
            if n >= 3 and span >= 1.0:  # a burst of a few is no rate
                out[kind] = (n - 1) / span
        return out

    def tracking_summary(self) -> dict[str, float | int]:
        """Tracking over the trajectory rows: RMS and max position error (m), rows."""
        if not self._track_n:
            return {"rows": 0}
        return {"rows": self._track_n, "rms_m": math.sqrt(self._track_sq / self._track_n),
                "max_m": self._track_max}

    @property
    def esc_seen(self) -> bool:
        """Whether any ESC rpm has arrived."""
        return self._esc_seen

    def close(self) -> None:
        """Write any rows held (without the IMU if still undecided); flush, fsync and
        close the pose log. Harmless twice."""
        self.use_imu(False)
        assert self._writer is not None
        self._writer.close()
