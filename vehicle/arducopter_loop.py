"""ArduCopter's closed loop in GUIDED with position, velocity and acceleration targets, as
numba kernels (one 400 Hz tick at a time).

Written from the structure of ArduCopter's controllers (ArduPilot 90700977, the build of
``../shared/sitl``), not from their code:

- **guided target**: each SET_POSITION_TARGET_LOCAL_NED sets position, velocity,
  acceleration, yaw and yaw rate; between messages the target moves on by its own velocity
  and acceleration, and the yaw by its rate (``ModeGuided::posvelaccel_control_run``,
  ``AutoYaw`` ANGLE_RATE).
- **input shaping** (``AC_PosControl::input_pos_vel_accel_NE/U``): a desired position,
  velocity and acceleration follow the target through square-root controllers whose
  acceleration is limited (``WPNAV_ACCEL``, ``WPNAV_ACCEL_Z``) and whose acceleration
  changes at most at the jerk limit (``PSC_JERK_XY``/``_Z``); the target's own
  acceleration is fed forward through the same jerk limit.
- **position controller** (``update_NE_controller``, ``update_U_controller``): P on
  position (square root at the correction acceleration), PID on velocity, the desired
  acceleration added, the horizontal acceleration cut at the lean angle
  (``ANGLE_MAX``/``PSC_ANGLE_MAX``); vertically a PID on acceleration sets the throttle
  around ``MOT_THST_HOVER``, boosted by 1/cos(tilt) and low-passed at 2 Hz by the motors.
  The thrust direction is the horizontal acceleration target against gravity alone.
- **attitude controller** (``input_thrust_vector_heading``, ``attitude_controller_run_quat``):
  an attitude target turned towards that thrust direction and the heading at body rates
  shaped by ``ATC_INPUT_TC`` with angular-acceleration limits ``ATC_ACCEL_R/P/Y_MAX``,
  rates limited by ``ATC_RATE_*_MAX`` and the yaw by ``ATC_SLEW_YAW``; the body follows
  the target by square-root angle controllers (``ATC_ANG_*_P``) plus the target's rates fed
  forward; the yaw error is held within what the yaw rate loop can correct (≤ 45°).
- **rate controller** (``AC_AttitudeControl_Multi::rate_controller_run``): a PID per axis
  (``ATC_RAT_*``: P, I, D, FF, IMAX, FLTT, FLTE, FLTD), its output (−1…1) a share of the
  largest torque the motor mixer gives that axis.

The vehicle is the paper's rigid body with its rotor drag (−T c_D v across the rotor
discs): thrust along body z, angular acceleration the rate loop's output times the axis'
torque per unit over its inertia (gyroscopic coupling left out), the yaw rate damped by the
same rotor drag acting at each rotor's own speed ω × r_i. Frames are world ENU and body
FLU: the controllers are symmetric, so ArduPilot's NED/FRD arithmetic carries over with z
up. Parameter and state
layouts are the module constants (``P_*``, ``S_*``); `mavsysid.vehicle.autopilot_loop`
fills them from an autopilot's parameters.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.loop_math import (
    clamp,
    inverse_sqrt_controller,
    limit_length,
    lowpass_alpha,
    shape_position_1d,
    shape_position_2d,
    sqrt_controller,
    thrust_heading_quaternion,
)
from mavsysid.vehicle.rotation import (
    conjugate_tuple,
    exp_tuple,
    log_tuple,
    multiply_tuple,
    normalized_tuple,
    rotate_inverse_tuple,
    rotate_tuple,
)

__all__ = ["PARAMETER_COUNT", "RECORD_COLUMNS", "STATE_SIZE", "initial_state", "kernel_parameters",
           "run_loop"]

# Parameter vector (SI; rate-loop gains in the autopilot's own normalised output units).
P_DT, P_JERK_XY, P_ACCEL_XY, P_SPEED_XY, P_JERK_Z, P_ACCEL_Z = 0, 1, 2, 3, 4, 5
P_SPEED_UP, P_SPEED_DOWN = 6, 7
P_POS_XY_P, P_CORR_SPEED_XY, P_CORR_ACCEL_XY = 8, 9, 10
P_POS_Z_P, P_CORR_SPEED_UP, P_CORR_SPEED_DOWN, P_CORR_ACCEL_Z = 11, 12, 13, 14
P_VXY_P, P_VXY_I, P_VXY_D, P_VXY_IMAX, P_VXY_FLTE, P_VXY_FLTD, P_VXY_FF = 15, 16, 17, 18, 19, 20, 21
P_VZ_P, P_VZ_I, P_VZ_FLTE = 22, 23, 24
P_AZ_P, P_AZ_I, P_AZ_IMAX, P_AZ_FLTE, P_HOVER, P_THROTTLE_HZ = 25, 26, 27, 28, 29, 30
P_TILT_MAX, P_INPUT_TC = 31, 32
P_ACCEL_RPY = 33          # 3: roll, pitch, yaw angular-acceleration limits, rad/s²
P_RATE_MAX = 36           # 3: roll, pitch, yaw rate limits, rad/s (0: none)
P_SLEW_YAW, P_RATE_FF = 39, 40
P_ANGLE_P = 41            # 3
P_RATE_PID = 44           # 3 × 9: P, I, D, FF, IMAX, FLTT, FLTE, FLTD, torque/J per unit
RATE_PID_SIZE = 9
P_DRAG = P_RATE_PID + 3 * RATE_PID_SIZE   # c_D, s/m: rotor drag −T c_D v_B,xy / m
P_YAW_DAMPING = P_DRAG + 1                 # yaw damping per thrust acceleration, s/m
PARAMETER_COUNT = P_DRAG + 2

# State vector.
S_TP, S_TV, S_TA, S_TYAW, S_TYAW_RATE = 0, 3, 6, 9, 10      # guided target
S_DP, S_DV, S_DA = 11, 14, 17                                # shaped (desired)
S_P, S_V, S_Q, S_W = 20, 23, 26, 30                          # vehicle
S_WDOT, S_ACC = 33, 36                                       # last accelerations
S_THR_FILT, S_AZ_I, S_AZ_E, S_THR_IN = 39, 40, 41, 42        # vertical loop
S_VXY_I, S_VXY_E, S_VXY_D = 43, 45, 47                       # velocity PID (2 each)
S_VZ_E, S_VZ_I = 49, 50
S_AT_Q, S_AT_W = 51, 55                                      # attitude target, its rates
S_RATE_T = 58                                                # body-rate target
S_RPID = 61                                                  # 3 × (T filt, E filt, D filt, I)
S_ACC_T, S_THRUST = 73, 76                                   # acceleration target, T/m
S_WDOT_MOTOR = 77                                            # motors' share of ω̇
STATE_SIZE = 80

#: Columns of a recorded row: t, p (3), v (3), a (3), q (4), ω (3), ω̇ (3), T/m, desired
#: position (3), attitude target (4), the motors' angular acceleration (3: ω̇ plus the
#: rotor drag's damping).
RECORD_COLUMNS = 31

_RP_ACCEL_MIN, _RP_ACCEL_MAX = math.radians(40.0), math.radians(720.0)
_Y_ACCEL_MIN, _Y_ACCEL_MAX = math.radians(10.0), math.radians(120.0)
_YAW_ERROR_MAX = math.radians(45.0)


def initial_state(position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                  yaw: float, yaw_rate: float, hover: float) -> np.ndarray:
    """A loop in steady flight on a reference: target, desired and vehicle on it, the
    attitude the thrust direction and heading give, integrators holding the acceleration.

    Parameters
    ----------
    position, velocity, acceleration : ndarray, shape (3,)
        m, m/s, m/s², world ENU.
    yaw, yaw_rate : float
        rad, rad/s (ENU).
    hover : float
        Hover throttle (``MOT_THST_HOVER``).
    """
    s = np.zeros(STATE_SIZE)
    for base in (S_TP, S_DP, S_P):
        s[base:base + 3] = position
    for base in (S_TV, S_DV, S_V):
        s[base:base + 3] = velocity
    for base in (S_TA, S_DA, S_ACC, S_ACC_T):
        s[base:base + 3] = acceleration
    s[S_TYAW], s[S_TYAW_RATE] = yaw, yaw_rate
    q = thrust_heading_quaternion(acceleration[0], acceleration[1], GRAVITY, yaw)
    s[S_Q:S_Q + 4] = q
    s[S_AT_Q:S_AT_Q + 4] = q
    up_in_body = rotate_inverse_tuple(q, (0.0, 0.0, 1.0))
    s[S_AT_W + 2] = s[S_W + 2] = s[S_RATE_T + 2] = yaw_rate * up_in_body[2]
    lift = (GRAVITY + acceleration[2]) / GRAVITY
    s[S_THRUST] = GRAVITY + acceleration[2]
    s[S_AZ_I] = hover * (lift - 1.0)
    s[S_THR_IN] = hover * lift
    s[S_THR_FILT] = hover * lift / max(rotate_tuple(q, (0.0, 0.0, 1.0))[2], 0.1)
    return s


@numba.njit(cache=True)
def _shape(P, s, dt):
    """Move the desired state on, shape it towards the target, move the target on."""
    for i in range(3):
        s[S_DP + i] += s[S_DV + i] * dt + 0.5 * s[S_DA + i] * dt * dt
        s[S_DV + i] += s[S_DA + i] * dt
    ax, ay = shape_position_2d(
        s[S_TP], s[S_TP + 1], s[S_TV], s[S_TV + 1], s[S_TA], s[S_TA + 1],
        s[S_DP], s[S_DP + 1], s[S_DV], s[S_DV + 1], s[S_DA], s[S_DA + 1],
        P[P_SPEED_XY], P[P_ACCEL_XY], P[P_JERK_XY], dt)
    s[S_DA], s[S_DA + 1] = ax, ay
    s[S_DA + 2] = shape_position_1d(
        s[S_TP + 2], s[S_TV + 2], s[S_TA + 2], s[S_DP + 2], s[S_DV + 2], s[S_DA + 2],
        -P[P_SPEED_DOWN], P[P_SPEED_UP], -min(P[P_ACCEL_Z], 7.5), P[P_ACCEL_Z], P[P_JERK_Z], dt)
    for i in range(3):
        s[S_TP + i] += s[S_TV + i] * dt + 0.5 * s[S_TA + i] * dt * dt
        s[S_TV + i] += s[S_TA + i] * dt
    s[S_TYAW] += s[S_TYAW_RATE] * dt


@numba.njit(cache=True)
def _limit_lean(vx, vy, ax, ay, accel_max):
    """The horizontal acceleration within ``accel_max``, the part across the direction of
    travel (vx, vy) kept first."""
    if ax * ax + ay * ay <= accel_max * accel_max:
        return ax, ay
    speed = math.sqrt(vx * vx + vy * vy)
    if speed <= 0.0:
        return limit_length(ax, ay, accel_max)
    ux, uy = vx / speed, vy / speed
    along = ux * ax + uy * ay
    cx, cy = ax - along * ux, ay - along * uy
    if cx * cx + cy * cy > accel_max * accel_max:
        cx, cy = limit_length(cx, cy, accel_max)
        return cx, cy
    room = math.sqrt(max(accel_max * accel_max - cx * cx - cy * cy, 0.0))
    along = clamp(along, -room, room)
    return cx + along * ux, cy + along * uy


@numba.njit(cache=True)
def _position_xy(P, s, dt):
    """Horizontal position P and velocity PID: the acceleration target (S_ACC_T x, y)."""
    kp, corr_accel = P[P_POS_XY_P], P[P_CORR_ACCEL_XY]
    ex, ey = s[S_DP] - s[S_P], s[S_DP + 1] - s[S_P + 1]
    error_max = inverse_sqrt_controller(P[P_CORR_SPEED_XY], kp, corr_accel)
    lx, ly = limit_length(ex, ey, error_max)
    if lx != ex or ly != ey:  # the desired position is dragged to the largest error
        s[S_DP], s[S_DP + 1] = s[S_P] + lx, s[S_P + 1] + ly
    norm = math.sqrt(lx * lx + ly * ly)
    c = sqrt_controller(norm, kp, corr_accel, 0.0) / norm if norm > 0.0 else 0.0
    alpha_e, alpha_d = lowpass_alpha(dt, P[P_VXY_FLTE]), lowpass_alpha(dt, P[P_VXY_FLTD])
    out = np.empty(2)
    for i in range(2):
        target = (lx, ly)[i] * c + s[S_DV + i]
        last = s[S_VXY_E + i]
        s[S_VXY_E + i] += alpha_e * (target - s[S_V + i] - last)
        s[S_VXY_D + i] += alpha_d * ((s[S_VXY_E + i] - last) / dt - s[S_VXY_D + i])
        s[S_VXY_I + i] += P[P_VXY_I] * s[S_VXY_E + i] * dt
        out[i] = target * P[P_VXY_FF]
    ix, iy = limit_length(s[S_VXY_I], s[S_VXY_I + 1], P[P_VXY_IMAX])
    s[S_VXY_I], s[S_VXY_I + 1] = ix, iy
    for i in range(2):
        out[i] += (P[P_VXY_P] * s[S_VXY_E + i] + s[S_VXY_I + i] + P[P_VXY_D] * s[S_VXY_D + i]
                   + s[S_DA + i])
    ax, ay = _limit_lean(s[S_DV], s[S_DV + 1], out[0], out[1],
                         GRAVITY * math.tan(P[P_TILT_MAX]))
    s[S_ACC_T], s[S_ACC_T + 1] = ax, ay


@numba.njit(cache=True)
def _position_z(P, s, dt):
    """Vertical position P, velocity PID and acceleration PID: the throttle (S_THR_IN)."""
    kp, corr_accel = P[P_POS_Z_P], P[P_CORR_ACCEL_Z]
    error = s[S_DP + 2] - s[S_P + 2]
    high = inverse_sqrt_controller(P[P_CORR_SPEED_UP], kp, corr_accel)
    low = -inverse_sqrt_controller(P[P_CORR_SPEED_DOWN], kp, corr_accel)
    if error > high or error < low:
        error = clamp(error, low, high)
        s[S_DP + 2] = s[S_P + 2] + error
    vel_target = sqrt_controller(error, kp, corr_accel, 0.0) + s[S_DV + 2]
    s[S_VZ_E] += lowpass_alpha(dt, P[P_VZ_FLTE]) * (vel_target - s[S_V + 2] - s[S_VZ_E])
    s[S_VZ_I] += P[P_VZ_I] * s[S_VZ_E] * dt
    accel_target = P[P_VZ_P] * s[S_VZ_E] + s[S_VZ_I] + s[S_DA + 2]
    s[S_ACC_T + 2] = accel_target
    s[S_AZ_E] += lowpass_alpha(dt, P[P_AZ_FLTE]) * (accel_target - s[S_ACC + 2] - s[S_AZ_E])
    imax = max(P[P_AZ_IMAX], P[P_HOVER])
    s[S_AZ_I] = clamp(s[S_AZ_I] + P[P_AZ_I] * s[S_AZ_E] * dt, -imax, imax)
    s[S_THR_IN] = P[P_AZ_P] * s[S_AZ_E] + s[S_AZ_I] + P[P_HOVER]


@numba.njit(cache=True)
def _thrust_rotation(target, body):
    """The attitude error from ``body`` to ``target`` as a thrust-vector tilt then a
    heading turn: (x, y of the tilt, z of the turn) rad in the body frame, the tilt
    quaternion and its angle."""
    tx, ty, tz = rotate_tuple(target, (0.0, 0.0, 1.0))
    bx, by, bz = rotate_tuple(body, (0.0, 0.0, 1.0))
    cx, cy, cz = by * tz - bz * ty, bz * tx - bx * tz, bx * ty - by * tx
    angle = math.acos(clamp(bx * tx + by * ty + bz * tz, -1.0, 1.0))
    length = math.sqrt(cx * cx + cy * cy + cz * cz)
    if length < 1e-12 or angle == 0.0:
        cx, cy, cz, length = 0.0, 0.0, 1.0, 1.0
    ax, ay, az = rotate_inverse_tuple(body, (cx / length, cy / length, cz / length))
    tilt = exp_tuple((ax * angle, ay * angle, az * angle))
    ex, ey, _ = log_tuple(tilt)
    turn = multiply_tuple(multiply_tuple(conjugate_tuple(tilt), conjugate_tuple(body)), target)
    ez = log_tuple(turn)[2]
    return ex, ey, ez, tilt, angle


@numba.njit(cache=True)
def _shaped_rate(error, input_tc, accel_max, rate, rate_ff, rate_max, dt):
    """The next target rate: the feed-forward plus a square-root correction of the angle
    error at 1/``input_tc``, within ``rate_max``, changed by at most ``accel_max · dt``."""
    desired = rate_ff + sqrt_controller(error, 1.0 / max(input_tc, 0.01), accel_max, dt)
    if rate_max > 0.0:
        desired = clamp(desired, -rate_max, rate_max)
    if accel_max > 0.0:
        return clamp(desired, rate - accel_max * dt, rate + accel_max * dt)
    return desired


@numba.njit(cache=True)
def _limit_rates(s, base, roll_max, pitch_max, yaw_max):
    """Body rates s[base:base+3] within the roll/pitch ellipse and the yaw limit (0: none)."""
    if roll_max > 0.0 and pitch_max > 0.0:
        x, y = s[base] / roll_max, s[base + 1] / pitch_max
        n = math.sqrt(x * x + y * y)
        if n > 1.0:
            s[base], s[base + 1] = x * roll_max / n, y * pitch_max / n
    else:
        if roll_max > 0.0:
            s[base] = clamp(s[base], -roll_max, roll_max)
        if pitch_max > 0.0:
            s[base + 1] = clamp(s[base + 1], -pitch_max, pitch_max)
    if yaw_max > 0.0:
        s[base + 2] = clamp(s[base + 2], -yaw_max, yaw_max)


@numba.njit(cache=True)
def _attitude_target(P, s, dt):
    """Turn the attitude target towards the thrust direction and heading (input shaping)."""
    qt = (s[S_AT_Q], s[S_AT_Q + 1], s[S_AT_Q + 2], s[S_AT_Q + 3])
    step = exp_tuple((s[S_AT_W] * dt, s[S_AT_W + 1] * dt, s[S_AT_W + 2] * dt))
    qt = normalized_tuple(multiply_tuple(qt, step))
    slew = P[P_SLEW_YAW]
    heading_rate = clamp(s[S_TYAW_RATE], -slew, slew)
    desired = thrust_heading_quaternion(s[S_ACC_T], s[S_ACC_T + 1], GRAVITY, s[S_TYAW])
    if P[P_RATE_FF] > 0.0:
        ex, ey, ez, _, _ = _thrust_rotation(desired, qt)
        tc = P[P_INPUT_TC]
        s[S_AT_W] = _shaped_rate(ex, tc, P[P_ACCEL_RPY], s[S_AT_W], 0.0, 0.0, dt)
        s[S_AT_W + 1] = _shaped_rate(ey, tc, P[P_ACCEL_RPY + 1], s[S_AT_W + 1], 0.0, 0.0, dt)
        s[S_AT_W + 2] = _shaped_rate(ez, tc, P[P_ACCEL_RPY + 2], s[S_AT_W + 2], heading_rate,
                                     slew, dt)
        _limit_rates(s, S_AT_W, P[P_RATE_MAX], P[P_RATE_MAX + 1], slew)
    else:
        qt = desired
        s[S_AT_W:S_AT_W + 3] = 0.0
    for i in range(4):
        s[S_AT_Q + i] = qt[i]


@numba.njit(cache=True)
def _attitude_control(P, s, dt):
    """Body-rate target from the attitude error (square root) and the target's rates."""
    qt = (s[S_AT_Q], s[S_AT_Q + 1], s[S_AT_Q + 2], s[S_AT_Q + 3])
    qb = (s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3])
    ex, ey, ez, tilt, _ = _thrust_rotation(qt, qb)
    yaw_rate_p = P[P_RATE_PID + 2 * RATE_PID_SIZE]
    if yaw_rate_p > 0.0 and P[P_ANGLE_P + 2] > 0.0:
        heading_accel = clamp(0.5 * P[P_ACCEL_RPY + 2], _Y_ACCEL_MIN, _Y_ACCEL_MAX)
        error_max = min(inverse_sqrt_controller(1.0 / yaw_rate_p, P[P_ANGLE_P + 2],
                                                heading_accel), _YAW_ERROR_MAX)
        if abs(ez) > error_max:  # the target is held within reach of the yaw loop
            ez = clamp(ez, -error_max, error_max)
            qt = multiply_tuple(multiply_tuple(qb, tilt), exp_tuple((0.0, 0.0, ez)))
            for i in range(4):
                s[S_AT_Q + i] = qt[i]
    errors = (ex, ey, ez)
    for i in range(3):
        low, high = ((_RP_ACCEL_MIN, _RP_ACCEL_MAX) if i < 2 else (_Y_ACCEL_MIN, _Y_ACCEL_MAX))
        accel = P[P_ACCEL_RPY + i]
        limit = clamp(0.5 * accel, low, high) if accel > 0.0 else 0.0
        s[S_RATE_T + i] = sqrt_controller(errors[i], P[P_ANGLE_P + i], limit, dt)
    _limit_rates(s, S_RATE_T, P[P_RATE_MAX], P[P_RATE_MAX + 1], P[P_RATE_MAX + 2])
    to_body = multiply_tuple(conjugate_tuple(qb), qt)
    fx, fy, fz = rotate_tuple(to_body, (s[S_AT_W], s[S_AT_W + 1], s[S_AT_W + 2]))
    s[S_RATE_T] += fx
    s[S_RATE_T + 1] += fy
    s[S_RATE_T + 2] += fz


@numba.njit(cache=True)
def _rate_control(P, s, dt):
    """Rate PIDs → the motors' angular acceleration (S_WDOT_MOTOR), outputs clipped at the
    mixer's ±1."""
    for i in range(3):
        g = P_RATE_PID + i * RATE_PID_SIZE
        kp, ki, kd, kff, imax = P[g], P[g + 1], P[g + 2], P[g + 3], P[g + 4]
        m = S_RPID + 4 * i
        s[m] += lowpass_alpha(dt, P[g + 5]) * (s[S_RATE_T + i] - s[m])
        last = s[m + 1]
        s[m + 1] += lowpass_alpha(dt, P[g + 6]) * (s[m] - s[S_W + i] - last)
        s[m + 2] += lowpass_alpha(dt, P[g + 7]) * ((s[m + 1] - last) / dt - s[m + 2])
        s[m + 3] = clamp(s[m + 3] + ki * s[m + 1] * dt, -imax, imax)
        out = clamp(kp * s[m + 1] + s[m + 3] + kd * s[m + 2] + kff * s[m], -1.0, 1.0)
        s[S_WDOT_MOTOR + i] = P[g + 8] * out


@numba.njit(cache=True)
def _plant(P, s, dt):
    """Throttle (boosted by tilt, low-passed) → thrust; the rigid body one step on."""
    q = (s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3])
    zx, zy, zz = rotate_tuple(q, (0.0, 0.0, 1.0))
    boosted = s[S_THR_IN] / clamp(zz, 0.1, 1.0)
    s[S_THR_FILT] = clamp(s[S_THR_FILT] + lowpass_alpha(dt, P[P_THROTTLE_HZ])
                          * (boosted - s[S_THR_FILT]), 0.0, 1.0)
    thrust = GRAVITY * s[S_THR_FILT] / P[P_HOVER]
    s[S_THRUST] = thrust
    # Rotor drag opposes the velocity across the rotor discs (paper Eq. drag).
    along = s[S_V] * zx + s[S_V + 1] * zy + s[S_V + 2] * zz
    drag = thrust * P[P_DRAG]
    s[S_ACC] = thrust * zx - drag * (s[S_V] - along * zx)
    s[S_ACC + 1] = thrust * zy - drag * (s[S_V + 1] - along * zy)
    s[S_ACC + 2] = thrust * zz - GRAVITY - drag * (s[S_V + 2] - along * zz)
    s[S_WDOT], s[S_WDOT + 1] = s[S_WDOT_MOTOR], s[S_WDOT_MOTOR + 1]
    # The rotors' drag at their own speed ω × r damps the yaw rate.
    s[S_WDOT + 2] = s[S_WDOT_MOTOR + 2] - P[P_YAW_DAMPING] * thrust * s[S_W + 2]
    for i in range(3):
        s[S_V + i] += s[S_ACC + i] * dt
        s[S_P + i] += s[S_V + i] * dt - 0.5 * s[S_ACC + i] * dt * dt
        s[S_W + i] += s[S_WDOT + i] * dt
    step = exp_tuple((s[S_W] * dt, s[S_W + 1] * dt, s[S_W + 2] * dt))
    q = normalized_tuple(multiply_tuple(q, step))
    for i in range(4):
        s[S_Q + i] = q[i]


@numba.njit(cache=True)
def _record(s, t, out, row):
    out[row, 0] = t
    for i in range(3):
        out[row, 1 + i] = s[S_P + i]
        out[row, 4 + i] = s[S_V + i]
        out[row, 7 + i] = s[S_ACC + i]
        out[row, 14 + i] = s[S_W + i]
        out[row, 17 + i] = s[S_WDOT + i]
        out[row, 21 + i] = s[S_DP + i]
        out[row, 28 + i] = s[S_WDOT_MOTOR + i]
    for i in range(4):
        out[row, 10 + i] = s[S_Q + i]
        out[row, 24 + i] = s[S_AT_Q + i]
    out[row, 20] = s[S_THRUST]


@numba.njit(cache=True)
def run_loop(P, setpoints, s, ticks, record_every, out):
    """Fly ``ticks`` ticks of ``P[P_DT]`` s from state ``s`` (updated in place).

    Parameters
    ----------
    P : ndarray, shape (PARAMETER_COUNT,)
    setpoints : ndarray, shape (M, 12)
        Rows [t, p (3), v (3), a (3), yaw, yaw rate], t in s from the start, increasing;
        each is applied at the first tick at or after its time.
    s : ndarray, shape (STATE_SIZE,)
    ticks : int
    record_every : int
        A row of ``out`` every this many ticks, the first at t = 0.
    out : ndarray, shape (ticks // record_every + 1, RECORD_COLUMNS)
    """
    dt = P[P_DT]
    j = 0
    for k in range(ticks + 1):
        t = k * dt
        while j < setpoints.shape[0] and setpoints[j, 0] <= t + 1e-9:
            s[S_TP:S_TP + 9] = setpoints[j, 1:10]
            s[S_TYAW], s[S_TYAW_RATE] = setpoints[j, 10], setpoints[j, 11]
            j += 1
        if k % record_every == 0:
            _record(s, t, out, k // record_every)
        if k == ticks:
            break
        _shape(P, s, dt)
        _position_xy(P, s, dt)
        _position_z(P, s, dt)
        _attitude_target(P, s, dt)
        _attitude_control(P, s, dt)
        _rate_control(P, s, dt)
        _plant(P, s, dt)


def kernel_parameters(values: dict[str, float], dt: float, plant: np.ndarray,
                      drag: float = 0.0, yaw_damping: float = 0.0) -> np.ndarray:
    """The parameter vector (SI) from ArduCopter's parameters in its own units.

    Parameters
    ----------
    values : dict
        Every name of `mavsysid.vehicle.autopilot_loop.ARDUCOPTER_LOOP_DEFAULTS`.
    dt : float
        Tick, s.
    plant : ndarray, shape (3,)
        Angular acceleration of one unit of rate-controller output per axis, rad/s².
    drag : float
        c_D, s/m.
    yaw_damping : float
        Yaw-rate damping of the rotor drag per unit thrust acceleration, s/m (its rate is
        this times T/m, 1/s).
    """
    v, cdeg = values, math.radians(0.01)
    P = np.zeros(PARAMETER_COUNT)
    P[P_DT] = dt
    accel_xy = 0.01 * v["WPNAV_ACCEL"]
    # The horizontal jerk also stays within what the roll/pitch acceleration allows.
    jerk_xy = v["PSC_JERK_XY"]
    snap = GRAVITY * min(v["ATC_ACCEL_R_MAX"], v["ATC_ACCEL_P_MAX"]) * cdeg
    if snap > 0.0 and v["ATC_RATE_FF_ENAB"] > 0.0:
        jerk_xy = min(jerk_xy, 0.5 * math.sqrt(accel_xy * snap))
    rates = [math.radians(v[f"ATC_RATE_{a}_MAX"]) for a in "RPY"]
    if min(rates[:2]) > 0.0 and v["ATC_RATE_FF_ENAB"] > 0.0:
        jerk_xy = min(jerk_xy, GRAVITY * min(rates[:2]))
    accel_z = 0.01 * v["WPNAV_ACCEL_Z"]
    P[P_JERK_XY], P[P_ACCEL_XY], P[P_SPEED_XY] = jerk_xy, accel_xy, 0.01 * v["WPNAV_SPEED"]
    # The vertical jerk stays within what the acceleration PID's error filter passes.
    P[P_JERK_Z] = min(v["PSC_JERK_Z"], min(GRAVITY, accel_z) * 2 * math.pi
                      * v["PSC_ACCZ_FLTE"] / 5.0) if v["PSC_ACCZ_FLTE"] > 0 else v["PSC_JERK_Z"]
    P[P_ACCEL_Z], P[P_SPEED_UP] = accel_z, 0.01 * v["WPNAV_SPEED_UP"]
    P[P_SPEED_DOWN] = 0.01 * v["WPNAV_SPEED_DN"]
    P[P_POS_XY_P], P[P_CORR_SPEED_XY], P[P_CORR_ACCEL_XY] = (v["PSC_POSXY_P"], P[P_SPEED_XY],
                                                            accel_xy)
    P[P_POS_Z_P], P[P_CORR_SPEED_UP] = v["PSC_POSZ_P"], P[P_SPEED_UP]
    P[P_CORR_SPEED_DOWN], P[P_CORR_ACCEL_Z] = P[P_SPEED_DOWN], accel_z
    P[P_VXY_P:P_VXY_FF + 1] = [v["PSC_VELXY_P"], v["PSC_VELXY_I"], v["PSC_VELXY_D"],
                               0.01 * v["PSC_VELXY_IMAX"], v["PSC_VELXY_FLTE"],
                               v["PSC_VELXY_FLTD"], v["PSC_VELXY_FF"]]
    P[P_VZ_P], P[P_VZ_I], P[P_VZ_FLTE] = v["PSC_VELZ_P"], v["PSC_VELZ_I"], v["PSC_VELZ_FLTE"]
    # Acceleration PID: cm/s² in, thousandths of throttle out.
    P[P_AZ_P], P[P_AZ_I] = 0.1 * v["PSC_ACCZ_P"], 0.1 * v["PSC_ACCZ_I"]
    P[P_AZ_IMAX], P[P_AZ_FLTE] = 0.001 * v["PSC_ACCZ_IMAX"], v["PSC_ACCZ_FLTE"]
    P[P_HOVER], P[P_THROTTLE_HZ] = v["MOT_THST_HOVER"], 2.0
    tilt = v["PSC_ANGLE_MAX"] if v["PSC_ANGLE_MAX"] > 0.0 else 0.01 * v["ANGLE_MAX"]
    P[P_TILT_MAX], P[P_INPUT_TC] = math.radians(tilt), v["ATC_INPUT_TC"]
    P[P_ACCEL_RPY:P_ACCEL_RPY + 3] = [cdeg * v[f"ATC_ACCEL_{a}_MAX"] for a in "RPY"]
    P[P_RATE_MAX:P_RATE_MAX + 3] = rates
    slew = 0.01 * v["ATC_SLEW_YAW"]
    if v["ATC_RATE_Y_MAX"] > 0.0:
        slew = min(slew, v["ATC_RATE_Y_MAX"])
    P[P_SLEW_YAW], P[P_RATE_FF] = math.radians(slew), v["ATC_RATE_FF_ENAB"]
    P[P_ANGLE_P:P_ANGLE_P + 3] = [v[f"ATC_ANG_{a}_P"] for a in ("RLL", "PIT", "YAW")]
    for i, axis in enumerate(("RLL", "PIT", "YAW")):
        base = P_RATE_PID + i * RATE_PID_SIZE
        P[base:base + 8] = [v[f"ATC_RAT_{axis}_{n}"] for n in
                            ("P", "I", "D", "FF", "IMAX", "FLTT", "FLTE", "FLTD")]
        P[base + 8] = plant[i]
    P[P_DRAG], P[P_YAW_DAMPING] = drag, yaw_damping
    return P
