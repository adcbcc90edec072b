"""The arithmetic of multirotor autopilot loops, as numba functions on scalars.

The building blocks `mavsysid.vehicle.arducopter_loop` and `mavsysid.vehicle.px4_loop`
assemble: the square-root controller (a P controller whose output's rate of change is
bounded, ArduPilot's ``sqrt_controller``), jerk-limited kinematic shaping towards a moving
target (ArduPilot's ``shape_pos_vel_accel``, one axis and the horizontal plane), first-order
low-pass filters, and the attitude of a thrust direction and heading. Written from the
documented behaviour of those functions; quaternions are [w, x, y, z], Hamilton, body →
world, and their arithmetic is `mavsysid.vehicle.rotation`'s tuple forms (nothing is
allocated per tick).
"""

from __future__ import annotations

import math

import numba
from mavsysid.vehicle.rotation import exp_tuple, multiply_tuple

__all__ = [
    "clamp",
    "inverse_sqrt_controller",
    "limit_length",
    "lowpass_alpha",
    "shape_position_1d",
    "shape_position_2d",
    "shape_velocity_1d",
    "shape_velocity_2d",
    "sqrt_controller",
    "thrust_heading_quaternion",
]


@numba.njit(cache=True)
def clamp(value: float, low: float, high: float) -> float:
    """``value`` limited to [low, high].

    Parameters
    ----------
    value, low, high : float
        The number and its bounds (low ≤ high).
    """
    return min(max(value, low), high)


@numba.njit(cache=True)
def limit_length(x: float, y: float, length: float) -> tuple[float, float]:
    """(x, y) scaled down to at most ``length`` (unchanged when ``length`` ≤ 0).

    Parameters
    ----------
    x, y : float
        The vector.
    length : float
        Its largest length.
    """
    norm = math.sqrt(x * x + y * y)
    if length > 0.0 and norm > length:
        return x * length / norm, y * length / norm
    return x, y


@numba.njit(cache=True)
def lowpass_alpha(dt: float, cutoff_hz: float) -> float:
    """The weight of a new sample in a first-order low-pass filter (1: no filter).

    Parameters
    ----------
    dt : float
        Sample period, s.
    cutoff_hz : float
        Cut-off frequency, Hz (≤ 0: no filter).
    """
    if cutoff_hz <= 0.0:
        return 1.0
    rc = 1.0 / (2.0 * math.pi * cutoff_hz)
    return dt / (dt + rc)


@numba.njit(cache=True)
def sqrt_controller(error: float, gain: float, rate_limit: float, dt: float) -> float:
    """Correction rate for ``error``: ``gain · error`` near zero, and beyond the distance
    where that would need more than ``rate_limit`` of second-order change, the speed from
    which that limit stops at zero, √(2 a (|e| − a/2k²)); no limit when ``rate_limit`` ≤ 0.
    With ``dt`` > 0 the output never overshoots the error within one step.

    Parameters
    ----------
    error : float
        The error to correct (any unit u).
    gain : float
        Linear gain, 1/s.
    rate_limit : float
        Largest rate of change of the correction, u/s².
    dt : float
        Step, s (0: no overshoot clamp).
    """
    if rate_limit <= 0.0:
        out = gain * error
    elif gain <= 0.0:
        out = math.copysign(math.sqrt(2.0 * rate_limit * abs(error)), error)
    else:
        linear = rate_limit / (gain * gain)
        if abs(error) > linear:
            out = math.copysign(math.sqrt(2.0 * rate_limit * (abs(error) - 0.5 * linear)),
                                error)
        else:
            out = gain * error
    if dt > 0.0:
        bound = abs(error) / dt
        out = clamp(out, -bound, bound)
    return out


@numba.njit(cache=True)
def inverse_sqrt_controller(output: float, gain: float, rate_limit: float) -> float:
    """The error for which `sqrt_controller` (without ``dt``) answers ``output``.

    Parameters
    ----------
    output : float
        The correction rate, u/s.
    gain, rate_limit : float
        As for `sqrt_controller`.
    """
    if rate_limit > 0.0 and gain <= 0.0:
        return output * output / (2.0 * rate_limit)
    if rate_limit <= 0.0:
        return output / gain if gain > 0.0 else 0.0
    if abs(output) < rate_limit / gain:
        return output / gain
    distance = 0.5 * rate_limit / (gain * gain) + output * output / (2.0 * rate_limit)
    return math.copysign(distance, output)


@numba.njit(cache=True)
def shape_velocity_1d(vel_in: float, accel_in: float, vel: float, accel: float,
                      accel_min: float, accel_max: float, jerk_max: float, dt: float) -> float:
    """The next acceleration of a shaped profile (one axis) towards ``vel_in`` with the
    feed-forward ``accel_in``: a square-root correction of the velocity error within
    [accel_min, accel_max], changed from ``accel`` by at most ``jerk_max · dt``.

    Parameters
    ----------
    vel_in, accel_in : float
        Requested velocity (m/s) and its acceleration feed-forward (m/s²).
    vel, accel : float
        The profile's velocity and acceleration now.
    accel_min, accel_max : float
        Acceleration range of the correction, m/s² (accel_min < 0 < accel_max).
    jerk_max : float
        m/s³.
    dt : float
        Step, s.
    """
    error = vel_in - vel
    gain = jerk_max / (accel_max if error > 0.0 else -accel_min)
    target = clamp(sqrt_controller(error, gain, jerk_max, dt), accel_min, accel_max)
    target += accel_in
    return accel + clamp(target - accel, -jerk_max * dt, jerk_max * dt)


@numba.njit(cache=True)
def shape_position_1d(pos_in: float, vel_in: float, accel_in: float, pos: float, vel: float,
                      accel: float, vel_min: float, vel_max: float, accel_min: float,
                      accel_max: float, jerk_max: float, dt: float) -> float:
    """`shape_velocity_1d` towards a position target: the velocity that closes the
    position error at half the acceleration limit (square root), within [vel_min,
    vel_max], plus the target's own velocity.

    Parameters
    ----------
    pos_in, vel_in, accel_in : float
        The target: position (m), velocity (m/s), acceleration (m/s²).
    pos, vel, accel : float
        The profile now.
    vel_min, vel_max : float
        Range of the position correction's velocity, m/s (both 0: none).
    accel_min, accel_max, jerk_max, dt : float
        As for `shape_velocity_1d`.
    """
    error = pos_in - pos
    if error > 0.0:
        brake, gain = -0.5 * accel_min, -0.5 * jerk_max / accel_min
    else:
        brake, gain = 0.5 * accel_max, 0.5 * jerk_max / accel_max
    vel_target = sqrt_controller(error, gain, brake, dt)
    if vel_min < 0.0 or vel_max > 0.0:
        vel_target = clamp(vel_target, vel_min, vel_max)
    return shape_velocity_1d(vel_target + vel_in, accel_in, vel, accel, accel_min, accel_max,
                             jerk_max, dt)


@numba.njit(cache=True)
def shape_velocity_2d(vx_in: float, vy_in: float, ax_in: float, ay_in: float, vx: float,
                      vy: float, ax: float, ay: float, accel_max: float, jerk_max: float,
                      dt: float) -> tuple[float, float]:
    """`shape_velocity_1d` in the horizontal plane: the correction along the error vector,
    its part across the requested velocity kept (up to 1/√2 of the limit) before the part
    along it, and the acceleration vector's change bounded by ``jerk_max · dt``.

    Parameters
    ----------
    vx_in, vy_in, ax_in, ay_in : float
        Requested velocity (m/s) and acceleration feed-forward (m/s²).
    vx, vy, ax, ay : float
        The profile's velocity and acceleration now.
    accel_max, jerk_max, dt : float
        Largest correction (m/s²), jerk (m/s³), step (s).
    """
    ex, ey = vx_in - vx, vy_in - vy
    norm = math.sqrt(ex * ex + ey * ey)
    cx = cy = 0.0
    if norm > 0.0:
        c = sqrt_controller(norm, jerk_max / accel_max, jerk_max, dt)
        cx, cy = ex * c / norm, ey * c / norm
    speed = math.sqrt(vx_in * vx_in + vy_in * vy_in)
    if speed <= 0.0:
        cx, cy = limit_length(cx, cy, accel_max)
    else:
        ux, uy = vx_in / speed, vy_in / speed
        along = ux * cx + uy * cy
        ax_cross, ay_cross = cx - along * ux, cy - along * uy
        if along * along <= ax_cross * ax_cross + ay_cross * ay_cross:
            cx, cy = limit_length(cx, cy, accel_max)
        else:
            ax_cross, ay_cross = limit_length(ax_cross, ay_cross, accel_max / math.sqrt(2.0))
            room = math.sqrt(max(accel_max * accel_max - ax_cross * ax_cross
                                 - ay_cross * ay_cross, 0.0))
            along = clamp(along, -room, room)
            cx, cy = ax_cross + along * ux, ay_cross + along * uy
    dx, dy = limit_length(cx + ax_in - ax, cy + ay_in - ay, jerk_max * dt)
    return ax + dx, ay + dy


@numba.njit(cache=True)
def shape_position_2d(px_in: float, py_in: float, vx_in: float, vy_in: float, ax_in: float,
                      ay_in: float, px: float, py: float, vx: float, vy: float, ax: float,
                      ay: float, vel_max: float, accel_max: float, jerk_max: float,
                      dt: float) -> tuple[float, float]:
    """`shape_velocity_2d` towards a horizontal position target (`shape_position_1d`'s
    square-root approach along the error vector, its speed at most ``vel_max``).

    Parameters
    ----------
    px_in, py_in, vx_in, vy_in, ax_in, ay_in : float
        The target's position (m), velocity (m/s), acceleration (m/s²).
    px, py, vx, vy, ax, ay : float
        The profile now.
    vel_max, accel_max, jerk_max, dt : float
        Largest correction speed (m/s), acceleration (m/s²), jerk (m/s³); step (s).
    """
    ex, ey = px_in - px, py_in - py
    norm = math.sqrt(ex * ex + ey * ey)
    cx = cy = 0.0
    if norm > 0.0:
        c = sqrt_controller(norm, 0.5 * jerk_max / accel_max, 0.5 * accel_max, dt)
        cx, cy = ex * c / norm, ey * c / norm
    cx, cy = limit_length(cx, cy, vel_max)
    return shape_velocity_2d(cx + vx_in, cy + vy_in, ax_in, ay_in, vx, vy, ax, ay, accel_max,
                             jerk_max, dt)


@numba.njit(cache=True)
def thrust_heading_quaternion(tx: float, ty: float, tz: float,
                              heading: float) -> tuple[float, float, float, float]:
    """The attitude whose body z axis is along the thrust vector (tx, ty, tz) (world ENU,
    z up), reached from the heading ``heading`` (rad about world z) by the shortest tilt:
    q = q_tilt ⊗ q_z(heading).

    Parameters
    ----------
    tx, ty, tz : float
        Thrust direction (any length; zero: straight up).
    heading : float
        rad.
    """
    n = math.sqrt(tx * tx + ty * ty + tz * tz)
    if n <= 0.0:
        tx, ty, tz, n = 0.0, 0.0, 1.0, 1.0
    tx, ty, tz = tx / n, ty / n, tz / n
    angle = math.acos(clamp(tz, -1.0, 1.0))
    ax, ay = -ty, tx  # up × t
    length = math.sqrt(ax * ax + ay * ay)
    if length < 1e-12:
        tilt = (1.0, 0.0, 0.0, 0.0)
    else:
        tilt = exp_tuple((ax / length * angle, ay / length * angle, 0.0))
    return multiply_tuple(tilt, (math.cos(0.5 * heading), 0.0, 0.0, math.sin(0.5 * heading)))
