"""The simulated autopilot's reference: a moving target, and a shaper that follows it.

The autopilot logic (`mavsysid.flight.simvehicle.autopilot`) only states *where the vehicle should
be*
as a target: position, velocity, acceleration (and an estimated jerk), yaw and yaw
rate, in world ENU. Between updates the target is extrapolated, ``p + v dt + ½ a dt²``
(plus ``j dt³/6`` for a short while after a setpoint), as ArduPilot's position
controller does with guided targets. A kinematic shaper turns the target into the
controller's reference row (`mavsysid.flight.offline.controller.REFERENCE_DIM`): a target that is
consistent in itself (feed-forward setpoints along a trajectory) passes through
unchanged, while a jump (a position-only setpoint 5 m away, a takeoff) is followed with
bounded speed and acceleration through a square-root controller, like ArduPilot's
``sqrt_controller`` shaping. The desired body rates come from the yaw rate and from the
target's jerk (differential flatness), which the streamed setpoints do not carry but
successive acceleration setpoints reveal.

Layouts (all float64 arrays, ENU/FLU, SI units):

- target (`TARGET_DIM`): p (3), v (3), a (3), j (3), yaw, yaw rate, use position xy
  (1/0), use position z (1/0), seconds of jerk extrapolation left.
- shaper state (`SHAPER_DIM`): p (3), v (3), yaw.
- limits (`LIMITS_DIM`): position gain (1/s), velocity gain (1/s), max horizontal
  speed, max climb rate, max descent rate (m/s), max horizontal and vertical
  acceleration correction (m/s²), yaw gain (1/s), max yaw-rate correction (rad/s).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from mavsysid.vehicle.flatness import SAMPLE_RATE, SAMPLE_SIZE, flat_sample
from mavsysid.vehicle.rotation import wrap_angle_kernel

__all__ = [
    "LIMITS_DIM",
    "PROFILE_SHARE",
    "SHAPER_DIM",
    "TARGET_DIM",
    "T_ACC",
    "T_JERK",
    "T_JERK_LEFT",
    "T_POS",
    "T_USE_XY",
    "T_USE_Z",
    "T_VEL",
    "T_YAW",
    "T_YAW_RATE",
    "hold_target",
    "shape_step",
]

#: Share of the acceleration limit the braking profile plans with.
PROFILE_SHARE = 0.8
TARGET_DIM = 17
SHAPER_DIM = 7
LIMITS_DIM = 9
T_POS = slice(0, 3)
T_VEL = slice(3, 6)
T_ACC = slice(6, 9)
T_JERK = slice(9, 12)
T_YAW = 12
T_YAW_RATE = 13
T_USE_XY = 14
T_USE_Z = 15
T_JERK_LEFT = 16


def hold_target(target: np.ndarray, position: np.ndarray, yaw: float) -> None:
    """Make ``target`` a fixed position and yaw, in place (the vehicle stops there)."""
    target[:] = 0.0
    target[T_POS] = position
    target[T_YAW] = yaw
    target[T_USE_XY] = 1.0
    target[T_USE_Z] = 1.0


@numba.njit(cache=True)
def _sqrt_controller(error, gain, accel):
    """ArduPilot's sqrt_controller: linear near zero, √(2 a |e|)-like far away."""
    if accel <= 0.0:
        return gain * error
    linear = accel / (gain * gain)
    if error > linear:
        return math.sqrt(2.0 * accel * (error - 0.5 * linear))
    if error < -linear:
        return -math.sqrt(2.0 * accel * (-error - 0.5 * linear))
    return gain * error


@numba.njit(cache=True)
def _sqrt_slope(error, gain, accel):
    """d(_sqrt_controller)/d(error), for |error| as given (≥ 0)."""
    if accel <= 0.0:
        return gain
    linear = accel / (gain * gain)
    if error > linear:
        return accel / math.sqrt(2.0 * accel * (error - 0.5 * linear))
    return gain


#: Inertia handed to the flatness kernel, which needs one for its torque; only the rates
#: it returns are used here.
_UNIT_INERTIA = np.ones(3)


@numba.njit(cache=True)
def _shaped_acceleration(target, state, limits, acc):
    """The shaper's acceleration (m/s², ENU) towards ``target`` into ``acc`` (3,).

    The target's own acceleration plus the correction of a velocity loop whose reference
    is the target's velocity and a braking profile of the position error, limited by
    ``limits`` (gains, speeds and accelerations; see the module docstring).
    """
    kp, kv = limits[0], limits[1]
    v_xy, v_up, v_down = limits[2], limits[3], limits[4]
    a_xy, a_z = limits[5], limits[6]
    # Position error → velocity correction along a braking profile (square root far
    # away), planned with part of the acceleration so that the velocity loop can keep up;
    # the profile's own rate of change is fed forward, so the reference brakes on time.
    ex, ey = target[0] - state[0], target[1] - state[1]
    e = math.sqrt(ex * ex + ey * ey)
    cx = cy = fx = fy = 0.0
    if e > 1e-9:
        ux, uy = ex / e, ey / e
        c = _sqrt_controller(e, kp, PROFILE_SHARE * a_xy)
        if c < v_xy:
            closing = (state[3] - target[3]) * ux + (state[4] - target[4]) * uy
            f = -_sqrt_slope(e, kp, PROFILE_SHARE * a_xy) * closing
            fx, fy = f * ux, f * uy
        else:
            c = v_xy
        cx, cy = c * ux, c * uy
    ez = target[2] - state[2]
    cz = _sqrt_controller(ez, kp, PROFILE_SHARE * a_z)
    fz = 0.0
    if -v_down < cz < v_up:
        fz = -_sqrt_slope(abs(ez), kp, PROFILE_SHARE * a_z) * (state[5] - target[5])
    else:
        cz = min(max(cz, -v_down), v_up)
    ax = fx + kv * (target[3] + cx - state[3])
    ay = fy + kv * (target[4] + cy - state[4])
    az = fz + kv * (target[5] + cz - state[5])
    an = math.sqrt(ax * ax + ay * ay)
    if an > a_xy:
        ax *= a_xy / an
        ay *= a_xy / an
    az = min(max(az, -a_z), a_z)
    acc[0] = target[6] + ax
    acc[1] = target[7] + ay
    acc[2] = target[8] + az


@numba.njit(cache=True)
def shape_step(target, state, limits, dt, ref):
    """Reference row at the current time into ``ref`` (16,); then advance by ``dt``.

    Both the shaper ``state`` and the ``target`` are advanced in place (the target
    extrapolated with its own derivatives), so that the next call is one tick later.
    """
    k_yaw, yaw_rate_max = limits[7], limits[8]
    use_xy = target[14] > 0.5
    use_z = target[15] > 0.5
    # A velocity-only axis carries its position target along with the vehicle's, so
    # that switching to a position target later starts from where the vehicle is.
    if not use_xy:
        target[0] = state[0]
        target[1] = state[1]
    if not use_z:
        target[2] = state[2]
    acc = np.empty(3)
    _shaped_acceleration(target, state, limits, acc)

    yaw_err = wrap_angle_kernel(target[12] - state[6])
    yaw_rate = target[13] + min(max(k_yaw * yaw_err, -yaw_rate_max), yaw_rate_max)

    jerk = np.zeros(3)
    if target[16] > 0.0:
        jerk[:] = target[9:12]
    for i in range(3):
        ref[i] = state[i]
        ref[3 + i] = state[3 + i]
        ref[6 + i] = acc[i]
        ref[13 + i] = 0.0
    ref[9] = state[6]
    # Desired body rates of the flat outputs a, j, ψ, ψ̇ (FLU, rad/s).
    flat = np.empty(SAMPLE_SIZE)
    if flat_sample(acc[0], acc[1], acc[2], jerk[0], jerk[1], jerk[2], 0.0, 0.0, 0.0,
                   state[6], yaw_rate, 0.0, _UNIT_INERTIA, flat):
        ref[10:13] = flat[SAMPLE_RATE:SAMPLE_RATE + 3]
    else:
        ref[10:13] = 0.0

    # Advance the shaper with the commanded acceleration, the target with its own.
    for i in range(3):
        state[i] += state[3 + i] * dt + 0.5 * acc[i] * dt * dt
        state[3 + i] += acc[i] * dt
        target[i] += (target[3 + i] * dt + 0.5 * target[6 + i] * dt * dt
                      + jerk[i] * dt * dt * dt / 6.0)
        target[3 + i] += target[6 + i] * dt + 0.5 * jerk[i] * dt * dt
        target[6 + i] += jerk[i] * dt
    state[6] = wrap_angle_kernel(state[6] + yaw_rate * dt)
    target[12] = wrap_angle_kernel(target[12] + target[13] * dt)
    if target[16] > 0.0:
        target[16] -= dt
        if target[16] <= 0.0:
            target[16] = 0.0
            target[9] = target[10] = target[11] = 0.0
