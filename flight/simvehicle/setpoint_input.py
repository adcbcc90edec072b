"""SET_POSITION_TARGET_LOCAL_NED as the simulated autopilots read it.

ArduPilot Copter (``GCS_MAVLink_Copter.cpp``): used only in GUIDED and not while
landed; frames LOCAL_NED (1), LOCAL_OFFSET_NED (7), BODY_NED (8), BODY_OFFSET_NED (9),
any other frame stops the vehicle. The type_mask works per group: any of bits 0–2 drops
the whole position, 3–5 the velocity, 6–8 the acceleration. Position, velocity,
acceleration, velocity+acceleration, position+velocity(+acceleration) are accepted;
anything else (position+acceleration without velocity, nothing at all) stops the
vehicle. Yaw (bit 10 clear) and yaw rate (bit 11 clear) apply together. After
GUID_TIMEOUT without a setpoint the velocity and acceleration feed-forward are dropped
and the position target held. PX4: frames 1 and 8 only (others are ignored), any
combination of the groups; setpoints count towards the OFFBOARD stream whatever the mode.

The target is converted to ENU at once (`mavsysid.vehicle.frames`). A jerk estimate from
successive acceleration setpoints, over the stream's own (smoothed) period, feeds the
body-rate reference for a short while (`mavsysid.flight.simvehicle.reference`).
"""

from __future__ import annotations

import math

import numpy as np
from mavsysid.flight.simvehicle.physics import SimVehicle
from mavsysid.flight.simvehicle.reference import (
    PROFILE_SHARE,
    T_ACC,
    T_JERK,
    T_JERK_LEFT,
    T_POS,
    T_USE_XY,
    T_USE_Z,
    T_VEL,
    T_YAW,
    T_YAW_RATE,
    hold_target,
)
from mavsysid.vehicle.frames import ned_to_enu, yaw_enu_to_ned, yaw_ned_to_enu, yaw_rate_ned_to_enu

__all__ = ["SetpointTracker"]

_ARDUPILOT_FRAMES = (1, 7, 8, 9)
_PX4_FRAMES = (1, 8)
_STREAM_GAP = 0.5       # s: a longer gap breaks the PX4 setpoint stream (> 2 Hz)
_STREAM_SPAN = 1.0      # s: how long the stream must have lasted for OFFBOARD
_JERK_MAX = 200.0       # m/s³: larger finite differences are jumps, not jerk
_JERK_HOLD_MAX = 0.1    # s: longest jerk extrapolation after a setpoint


class SetpointTracker:
    """Reads setpoints into the vehicle's target and keeps the stream's timing.

    Parameters
    ----------
    vehicle : SimVehicle
    ardupilot : bool
        ArduPilot rules (else PX4).
    """

    def __init__(self, vehicle: SimVehicle, ardupilot: bool) -> None:
        self.vehicle = vehicle
        self.ardupilot = ardupilot
        self.received = 0
        self.applied = 0
        self.last_t = -math.inf
        self._run_start = -math.inf
        self._latest: np.ndarray | None = None
        self._feed_forward = False  # a guided velocity/acceleration target is active
        self._prev_acc: np.ndarray | None = None
        self._prev_t = -math.inf
        self._period: float | None = None
        self._outliers = 0

    # --- stream timing ---------------------------------------------------------------
    def age(self, t: float) -> float:
        """Seconds since the last setpoint (inf before the first)."""
        return t - self.last_t

    def streaming(self, t: float) -> bool:
        """PX4's condition for OFFBOARD: setpoints at > 2 Hz for more than 1 s, until now."""
        return self.age(t) <= _STREAM_GAP and t - self._run_start >= _STREAM_SPAN

    # --- reception ---------------------------------------------------------------------
    def receive(self, msg, t: float, in_control: bool) -> bool:
        """Take one setpoint at sim time ``t``; True when it now steers the vehicle.

        ``in_control``: the vehicle is in the mode that follows setpoints (GUIDED,
        OFFBOARD).
        """
        self.received += 1
        v = self.vehicle
        frames = _ARDUPILOT_FRAMES if self.ardupilot else _PX4_FRAMES
        if self.ardupilot and not in_control:
            return False
        if msg.coordinate_frame not in frames:
            if self.ardupilot and not v.landed:
                self.stop_here()
            return False
        if not self.ardupilot and t - self.last_t > _STREAM_GAP:
            self._run_start = t
        self.last_t = t
        if self.ardupilot and v.landed:
            return False
        target = self._decode(msg, t)
        if target is None:
            if self.ardupilot and in_control:
                self.stop_here()
            return False
        if not self.ardupilot:
            self._latest = target
            if not in_control:
                return False
        v.target[:] = target
        self._feed_forward = True
        self.applied += 1
        return True

    def apply_latest(self, t: float) -> bool:
        """On entering OFFBOARD: steer by the last setpoint received, if any."""
        if self._latest is None:
            return False
        self.vehicle.target[:] = self._latest
        self._feed_forward = True
        return True

    def climbs(self) -> bool:
        """Whether the current target asks a landed vehicle to rise."""
        tgt, v = self.vehicle.target, self.vehicle
        if tgt[T_USE_Z] > 0.5 and tgt[2] > v.ground_z + 0.1:
            return True
        return tgt[5] > 0.1 or tgt[8] > 0.5

    def check_timeout(self, t: float, timeout: float) -> None:
        """ArduPilot's GUID_TIMEOUT: drop velocity/acceleration feed-forward, hold position."""
        if self._feed_forward and timeout > 0.0 and self.age(t) > timeout:
            self._feed_forward = False
            tgt = self.vehicle.target
            tgt[T_VEL] = 0.0
            tgt[T_ACC] = 0.0
            tgt[T_JERK] = 0.0
            tgt[T_JERK_LEFT] = 0.0
            tgt[T_YAW_RATE] = 0.0

    def stop_here(self) -> None:
        """Hold at the point where the reference can stop with its acceleration limit."""
        v = self.vehicle
        s, lim = v.shaper, v.limits
        stop = s[0:3].copy()
        speed_xy = math.hypot(s[3], s[4])
        if speed_xy > 0.0:
            stop[0:2] += s[3:5] * speed_xy / (2.0 * PROFILE_SHARE * lim[5])
        stop[2] += s[5] * abs(s[5]) / (2.0 * PROFILE_SHARE * lim[6])
        hold_target(v.target, stop, s[6])
        self._feed_forward = False

    # --- decoding ------------------------------------------------------------------------
    def _decode(self, msg, t: float) -> np.ndarray | None:
        """The ENU target a setpoint asks for; None when it means "stop" (or nothing)."""
        mask = msg.type_mask
        use_pos, use_vel, use_acc = not mask & 0x7, not mask & 0x38, not mask & 0x1C0
        if self.ardupilot and not (use_vel or (use_pos != use_acc)):
            return None  # neither velocity nor exactly one of position/acceleration
        if not (use_pos or use_vel or use_acc):
            return None
        v = self.vehicle
        frame = msg.coordinate_frame
        yaw_ned = float(yaw_enu_to_ned(v.yaw()))
        c, s = math.cos(yaw_ned), math.sin(yaw_ned)

        def vector(x: float, y: float, z: float, rotate: bool) -> np.ndarray:
            if rotate:  # body-heading axes → north/east
                x, y = x * c - y * s, x * s + y * c
            return ned_to_enu(np.array([x, y, z]))

        body = frame in (8, 9)
        tgt = v.target.copy()
        tgt[T_JERK] = 0.0
        tgt[T_JERK_LEFT] = 0.0
        if use_pos:
            p = vector(msg.x, msg.y, msg.z, body)
            if frame != 1:
                p += v.position
            tgt[T_POS] = p
        tgt[T_USE_XY] = tgt[T_USE_Z] = 1.0 if use_pos else 0.0
        if use_vel:
            tgt[T_VEL] = vector(msg.vx, msg.vy, msg.vz, body)
        elif use_pos:
            tgt[T_VEL] = 0.0
        else:
            tgt[T_VEL] = v.shaper[3:6]
        tgt[T_ACC] = vector(msg.afx, msg.afy, msg.afz, body) if use_acc else 0.0
        if use_acc:
            self._estimate_jerk(tgt, t)
        else:
            self._prev_acc = None

        use_yaw, use_rate = not msg.type_mask & 1024, not msg.type_mask & 2048
        if use_yaw and math.isfinite(msg.yaw):
            yaw_enu = float(yaw_ned_to_enu(msg.yaw))
            tgt[T_YAW] = v.yaw() - msg.yaw if frame == 9 else yaw_enu
        else:
            tgt[T_YAW] = v.shaper[6]
        use_rate = use_rate and math.isfinite(msg.yaw_rate)
        tgt[T_YAW_RATE] = float(yaw_rate_ned_to_enu(msg.yaw_rate)) if use_rate else 0.0
        if not np.all(np.isfinite(tgt)):
            return None
        return tgt

    def _estimate_jerk(self, tgt: np.ndarray, t: float) -> None:
        """Jerk from the last two acceleration setpoints, over the stream's period."""
        acc = tgt[T_ACC].copy()
        prev, prev_t = self._prev_acc, self._prev_t
        self._prev_acc, self._prev_t = acc, t
        if prev is None:
            return
        dt_rx = t - prev_t
        # Receipt times are quantised to control ticks; the sender's period is steady,
        # so a smoothed period gives a better Δt than each receipt interval.
        period = self._period
        if period is None or not 0.5 * period < dt_rx < 1.5 * period:
            self._outliers += 1
            if period is None or self._outliers >= 3:
                self._period, self._outliers = dt_rx, 0
        else:
            self._outliers = 0
            self._period = period + 0.05 * (dt_rx - period)
        if self._period is None or self._period <= 0.0:
            return
        steps = round(dt_rx / self._period)
        if not 1 <= steps <= 3:
            return
        dt = steps * self._period
        jerk = (acc - prev) / dt
        if np.linalg.norm(jerk) > _JERK_MAX:
            return
        tgt[T_JERK] = jerk
        tgt[T_JERK_LEFT] = min(1.5 * dt, _JERK_HOLD_MAX)
