"""Setpoints: what SET_POSITION_TARGET_LOCAL_NED carries, and when it is sent.

A `Setpoint` is a flat-output sample in world ENU (the rest of mavsysid's frame); it
becomes the message's NED fields only in `Setpoint.message_fields`, at the link boundary.
It carries position, velocity, acceleration, yaw and yaw rate with ``type_mask`` 0:
ArduPilot Copter applies full feed-forward only so (its mask works per group, and yaw
and yaw rate are applied together), and PX4 accepts the same.

`TickSchedule` is the drift-free clock of the stream: tick k is due at ``start + k·T``
however late earlier ticks were sent, and a tick that could not be sent before the next
one was due is dropped (counted), never sent late in a burst.

`SmoothMove` is a rest-to-rest quintic move between two poses (take-off to the start,
fly to the start), so that even these transfers carry consistent feed-forward.

`SetpointLimits` is the last line of defence: the stream asks it about every setpoint
before sending (`SetpointLimits.violation`, a few µs of plain float arithmetic), and a
setpoint outside the operator's box or beyond the vehicle's limits is never sent
(`UnsafeSetpoint`). The limits are derived from the vehicle in
`mavsysid.flight.ground.trajectory_safety.flight_limits`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.frames import enu_to_ned, yaw_enu_to_ned, yaw_rate_enu_to_ned
from mavsysid.vehicle.rotation import wrap_angle
from mavsysid.vehicle.trajectory import Trajectory

from mavsysid.errors import JobFailedError

__all__ = [
    "MAV_FRAME_LOCAL_NED",
    "TYPE_MASK_FULL",
    "Setpoint",
    "SetpointLimits",
    "SmoothMove",
    "TickSchedule",
    "UnsafeSetpoint",
    "hold",
    "trajectory_setpoint",
]

MAV_FRAME_LOCAL_NED = 1
#: Position, velocity, acceleration, yaw and yaw rate all used.
TYPE_MASK_FULL = 0


@dataclass(frozen=True)
class Setpoint:
    """One setpoint, world ENU.

    Attributes
    ----------
    position, velocity, acceleration : tuple of 3 float
        m, m/s, m/s².
    yaw : float
        rad, ENU (from x_W towards y_W), not wrapped.
    yaw_rate : float
        rad/s, ENU.
    t_traj : float
        Trajectory time it samples, s; −1 outside the trajectory (transfers, holds).
    """

    position: tuple[float, float, float]
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acceleration: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    yaw_rate: float = 0.0
    t_traj: float = -1.0

    def advanced(self, dt: float) -> Setpoint:
        """The setpoint carried ``dt`` s ahead along its own velocity and acceleration.

        What an autopilot targets between setpoints (ArduPilot integrates guided targets
        so): p + v dt + ½ a dt², v + a dt, ψ + ψ̇ dt; ``t_traj`` advances too (if ≥ 0).
        """
        p, v, a = (np.asarray(u, dtype=float)
                   for u in (self.position, self.velocity, self.acceleration))
        return Setpoint(tuple((p + v * dt + 0.5 * a * dt * dt).tolist()),
                        tuple((v + a * dt).tolist()), self.acceleration,
                        self.yaw + self.yaw_rate * dt, self.yaw_rate,
                        self.t_traj + dt if self.t_traj >= 0.0 else self.t_traj)

    def message_fields(self) -> dict[str, float | int]:
        """The SET_POSITION_TARGET_LOCAL_NED fields: frame LOCAL_NED, type_mask 0, NED.

        Keys: ``coordinate_frame, type_mask, x, y, z, vx, vy, vz, afx, afy, afz, yaw,
        yaw_rate`` (m, m/s, m/s², rad in (−π, π], rad/s).
        """
        p, v, a = (enu_to_ned(np.asarray(u, dtype=float)).tolist()
                   for u in (self.position, self.velocity, self.acceleration))
        return {"coordinate_frame": MAV_FRAME_LOCAL_NED, "type_mask": TYPE_MASK_FULL,
                "x": p[0], "y": p[1], "z": p[2], "vx": v[0], "vy": v[1], "vz": v[2],
                "afx": a[0], "afy": a[1], "afz": a[2],
                "yaw": float(yaw_enu_to_ned(self.yaw)),
                "yaw_rate": float(yaw_rate_enu_to_ned(self.yaw_rate))}


class UnsafeSetpoint(JobFailedError):
    """A setpoint outside the box or beyond the limits was about to be sent (it was not)."""


@dataclass(frozen=True)
class SetpointLimits:
    """What a setpoint may ask of the vehicle (world ENU, SI).

    Attributes
    ----------
    box : tuple of 6 float
        The operator's box [x_min, y_min, z_min, x_max, y_max, z_max], m.
    floor : float
        Lowest z a setpoint may have, m: the streamer's own climb from the ground and
        descent run below the box, in the column under it.
    speed_max : float
        ‖v‖, m/s.
    thrust_acceleration_min, thrust_acceleration_max : float
        ‖a − g‖ = collective thrust / mass, m/s².
    jerk_max : float
        ‖j‖, m/s³ (trajectories only: a setpoint carries no jerk).
    yaw_rate_max, yaw_acceleration_max : float
        |ψ̇|, rad/s; |ψ̈|, rad/s² (trajectories only).
    tolerance : float
        Slack for rounding: m on the box, relative on the other limits.
    """

    box: tuple[float, ...]
    floor: float
    speed_max: float
    thrust_acceleration_min: float
    thrust_acceleration_max: float
    jerk_max: float
    yaw_rate_max: float
    yaw_acceleration_max: float
    tolerance: float = 1e-6

    def violation(self, sp: Setpoint) -> str | None:
        """None if ``sp`` may be sent, else one line naming the quantity, value and limit.

        Written with ``not (x <= limit)`` so that NaN is a violation too.
        """
        b, tol = self.box, self.tolerance
        for i, axis in enumerate("xyz"):
            lo = self.floor if i == 2 else b[i]
            if not (lo - tol <= sp.position[i] <= b[i + 3] + tol):
                return (f"setpoint {axis} = {sp.position[i]:.3f} m outside the box "
                        f"[{lo:g}, {b[i + 3]:g}] m")
        vx, vy, vz = sp.velocity
        ax, ay, az = sp.acceleration
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        thrust = math.sqrt(ax * ax + ay * ay + (az + GRAVITY) ** 2)
        slack = 1.0 + tol
        checks = (("speed", speed, self.speed_max, "m/s"),
                  ("thrust acceleration |a - g|", thrust, self.thrust_acceleration_max,
                   "m/s²"),
                  ("yaw rate", abs(sp.yaw_rate), self.yaw_rate_max, "rad/s"))
        for name, value, limit, unit in checks:
            if not (value <= limit * slack):
                return f"setpoint {name} {value:.3g} {unit} beyond the limit {limit:.3g} {unit}"
        if not (thrust * slack >= self.thrust_acceleration_min) or not math.isfinite(sp.yaw):
            return (f"setpoint thrust acceleration |a - g| {thrust:.3g} m/s² below the limit "
                    f"{self.thrust_acceleration_min:.3g} m/s² (or a non-finite yaw)")
        return None

    def refusal(self, sp: Setpoint) -> str | None:
        """None if ``sp`` may be sent, else the one-line "unsafe setpoint not sent: …"."""
        if (why := self.violation(sp)) is None:
            return None
        at = f" (trajectory t = {sp.t_traj:.2f} s)" if sp.t_traj >= 0.0 else ""
        return f"unsafe setpoint not sent: {why}{at}"


def hold(position: np.ndarray, yaw: float) -> Setpoint:
    """Hover at ``position`` (m, ENU) with heading ``yaw`` (rad, ENU)."""
    p = np.asarray(position, dtype=float)
    return Setpoint((float(p[0]), float(p[1]), float(p[2])), yaw=float(yaw))


def trajectory_setpoint(trajectory: Trajectory, t: float) -> Setpoint:
    """The trajectory's flat outputs at time ``t`` (s; held at the ends outside).

    ``t_traj`` is ``t`` clipped to [0, duration].
    """
    tc = min(max(t, 0.0), trajectory.duration)
    f = trajectory.flat_outputs(np.array([tc]))
    return Setpoint(tuple(f.position[0].tolist()), tuple(f.velocity[0].tolist()),
                    tuple(f.acceleration[0].tolist()), float(f.yaw[0]), float(f.yaw_rate[0]),
                    t_traj=tc)


@dataclass(frozen=True)
class SmoothMove:
    """A rest-to-rest move from one pose to another with a quintic time law.

    s(u) = 10u³ − 15u⁴ + 6u⁵ for u = t/T has zero velocity and acceleration at both
    ends; peak speed is 1.875·d/T. The yaw turns the short way round.

    Attributes
    ----------
    start, end : tuple of 3 float
        Positions, m, ENU.
    yaw_start, yaw_end : float
        Headings, rad, ENU.
    duration : float
        T, s.
    """

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    yaw_start: float
    yaw_end: float
    duration: float

    @classmethod
    def between(cls, start: np.ndarray, yaw_start: float, end: np.ndarray, yaw_end: float,
                max_speed: float = 1.0, max_yaw_rate: float = 0.5,
                min_duration: float = 1.0) -> SmoothMove:
        """The shortest move within ``max_speed`` (m/s) and ``max_yaw_rate`` (rad/s).

        ``yaw_end`` is kept as given (the trajectory's continuous yaw); only the turn is
        taken the short way.
        """
        s, e = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        turn = float(wrap_angle(yaw_end - yaw_start))
        t = max(min_duration, 1.875 * float(np.linalg.norm(e - s)) / max_speed,
                1.875 * abs(turn) / max_yaw_rate)
        return cls(tuple(s.tolist()), tuple(e.tolist()), float(yaw_end - turn),
                   float(yaw_end), t)

    def setpoint(self, t: float) -> Setpoint:
        """The move at time ``t`` (s since its start; held at the ends)."""
        T = self.duration
        u = min(max(t / T, 0.0), 1.0)
        s = u**3 * (10.0 - 15.0 * u + 6.0 * u**2)
        ds = 30.0 * u**2 * (1.0 - u) ** 2 / T
        dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / T**2
        p0, p1 = np.asarray(self.start), np.asarray(self.end)
        d = p1 - p0
        turn = self.yaw_end - self.yaw_start
        return Setpoint(tuple((p0 + s * d).tolist()), tuple((ds * d).tolist()),
                        tuple((dds * d).tolist()), self.yaw_start + s * turn, ds * turn)


@dataclass
class TickSchedule:
    """Drift-free periodic ticks: tick k is due at ``start + k·period`` (streamer s).

    Call `due` when woken: it returns the index of the tick to send now (the latest one
    due), counting the ticks skipped over as dropped and a tick sent more than
    ``late_tolerance`` after its due time as late. Send times are kept for statistics.

    Attributes
    ----------
    start, period : float
        s.
    late_tolerance : float
        s; default a tenth of the period.
    sent, dropped, late : int
    send_times : list of float
        When each tick was sent, streamer s.
    """

    start: float
    period: float
    late_tolerance: float | None = None
    sent: int = 0
    dropped: int = 0
    late: int = 0
    next_tick: int = 0
    send_times: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not (self.period > 0.0 and math.isfinite(self.period)):
            raise ValueError(f"period must be a positive number of s, got {self.period!r}")
        if self.late_tolerance is None:
            self.late_tolerance = 0.1 * self.period

    def deadline(self, k: int | None = None) -> float:
        """When tick ``k`` (the next one by default) is due, s.

        A billionth of a period early, as `due` rounds: a clock that reads exactly the due
        time (lock-step: a frame's time) finds the tick due whichever way the sum rounded.
        """
        k = self.next_tick if k is None else k
        return self.start + (k - 1e-9) * self.period

    def due(self, now: float) -> int | None:
        """The tick to send at ``now``, or None if none is due yet; marks it sent."""
        if now < self.deadline():
            return None
        k = max(self.next_tick, math.floor((now - self.start) / self.period + 1e-9))
        self.dropped += k - self.next_tick
        if now - self.deadline(k) > self.late_tolerance:
            self.late += 1
        self.next_tick = k + 1
        self.sent += 1
        self.send_times.append(now)
        return k

    def statistics(self) -> dict[str, float | int]:
        """Achieved rate (Hz), period deviation from nominal (mean, p99, max |Δ|, s),
        counts of ticks sent, dropped and late."""
        times = np.asarray(self.send_times, dtype=float)
        out: dict[str, float | int] = {"sent": self.sent, "dropped": self.dropped,
                                       "late": self.late, "nominal_rate_hz": 1.0 / self.period}
        if times.size >= 2:
            dev = np.abs(np.diff(times) - self.period)
            out.update(rate_hz=float((times.size - 1) / (times[-1] - times[0])),
                       period_deviation_mean_s=float(dev.mean()),
                       period_deviation_p99_s=float(np.percentile(dev, 99)),
                       period_deviation_max_s=float(dev.max()))
        return out
