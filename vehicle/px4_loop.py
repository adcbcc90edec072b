"""PX4's closed loop in OFFBOARD with position, velocity and acceleration setpoints, as
numba kernels.

Written from PX4's documented controller structure (PX4 user guide, "Controller
Diagrams"; v1.15 parameter reference), not from its code:

- **setpoint**: an offboard trajectory setpoint is used as it is until the next one (no
  smoothing and no extrapolation in OFFBOARD; PX4's jerk-limited generators serve its own
  auto modes).
- **position control** (``mc_pos_control``): P on position (``MPC_XY_P``, ``MPC_Z_P``)
  plus the velocity feed-forward, limited to ``MPC_XY_VEL_MAX`` and
  ``MPC_Z_VEL_MAX_UP``/``_DN``; PID on velocity (``MPC_*_VEL_P/I/D_ACC``, D on the
  measured acceleration) plus the acceleration feed-forward; the thrust direction is the
  horizontal acceleration against gravity, tilted at most ``MPC_TILTMAX_AIR``; the
  collective thrust scales the vertical acceleration by ``MPC_THR_HOVER``, divided by
  the tilt's cosine.
- **attitude control** (``mc_att_control``): the attitude setpoint from the thrust
  direction and yaw (x_B perpendicular to the yaw's y axis); the tilt error corrected
  first and the yaw error weighted by ``MC_YAW_WEIGHT``, P gains ``MC_ROLL_P``,
  ``MC_PITCH_P``, ``MC_YAW_P``, the yaw rate setpoint fed forward, rates limited to
  ``MC_*RATE_MAX``.
- **rate control** (``mc_rate_control``): a PID per axis (``MC_*RATE_P/I/D`` times
  ``MC_*RATE_K``, D on the measured angular acceleration filtered at
  ``IMU_DGYRO_CUTOFF``), the output (−1…1) a share of the axis' largest mixer torque.

The vehicle is the rigid body of `mavsysid.vehicle.arducopter_loop` (with its rotor drag
and yaw damping; thrust at once, no motor filter). Same record layout as that module.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.loop_math import clamp, limit_length, lowpass_alpha
from mavsysid.vehicle.rotation import (
    conjugate_tuple,
    exp_tuple,
    log_tuple,
    matrix_to_quat_tuple,
    multiply_tuple,
    normalized_tuple,
    rotate_inverse_tuple,
    rotate_tuple,
)

__all__ = ["PARAMETER_COUNT", "RECORD_COLUMNS", "STATE_SIZE", "initial_state",
           "kernel_parameters", "run_loop"]

P_DT, P_XY_P, P_Z_P, P_VXY_P, P_VXY_I, P_VXY_D, P_VZ_P, P_VZ_I, P_VZ_D = range(9)
P_VXY_MAX, P_VUP, P_VDN, P_TILT, P_HOVER = 9, 10, 11, 12, 13
P_ATT_P, P_YAW_W, P_RATE_MAX = 14, 17, 18        # 3, 1, 3
P_RATE_PID, RATE_PID_SIZE = 21, 5                # per axis: P, I, D, K, torque/J per unit
P_DCUT, P_DRAG, P_YAW_DAMPING = 36, 37, 38
PARAMETER_COUNT = 39

S_TP, S_TV, S_TA, S_TYAW, S_TYAW_RATE = 0, 3, 6, 9, 10
S_P, S_V, S_Q, S_W, S_WDOT, S_ACC = 11, 14, 17, 21, 24, 27
S_VI, S_QD, S_RATE_T = 30, 33, 37
S_RPID = 40                                      # per axis: I, filtered ω̇, last ω
S_ACC_T, S_THRUST, S_WDOT_MOTOR = 49, 52, 53
STATE_SIZE = 56
RECORD_COLUMNS = 31
_INTEGRATOR_LIMIT = 0.3


def kernel_parameters(values: dict[str, float], dt: float, plant: np.ndarray,
                      drag: float = 0.0, yaw_damping: float = 0.0) -> np.ndarray:
    """The parameter vector (SI) from PX4's parameters in its own units.

    Parameters
    ----------
    values : dict
        Every name of `mavsysid.vehicle.autopilot_loop.PX4_LOOP_DEFAULTS`.
    dt, plant, drag, yaw_damping
        As for `mavsysid.vehicle.arducopter_loop.kernel_parameters`.
    """
    v = values
    P = np.zeros(PARAMETER_COUNT)
    P[P_DT], P[P_XY_P], P[P_Z_P] = dt, v["MPC_XY_P"], v["MPC_Z_P"]
    P[P_VXY_P:P_VZ_D + 1] = [v["MPC_XY_VEL_P_ACC"], v["MPC_XY_VEL_I_ACC"],
                             v["MPC_XY_VEL_D_ACC"], v["MPC_Z_VEL_P_ACC"],
                             v["MPC_Z_VEL_I_ACC"], v["MPC_Z_VEL_D_ACC"]]
    P[P_VXY_MAX], P[P_VUP], P[P_VDN] = (v["MPC_XY_VEL_MAX"], v["MPC_Z_VEL_MAX_UP"],
                                        v["MPC_Z_VEL_MAX_DN"])
    P[P_TILT], P[P_HOVER] = math.radians(v["MPC_TILTMAX_AIR"]), v["MPC_THR_HOVER"]
    P[P_ATT_P:P_ATT_P + 3] = [v["MC_ROLL_P"], v["MC_PITCH_P"], v["MC_YAW_P"]]
    P[P_YAW_W] = clamp(v["MC_YAW_WEIGHT"], 0.0, 1.0)
    for i, axis in enumerate(("ROLL", "PITCH", "YAW")):
        P[P_RATE_MAX + i] = math.radians(v[f"MC_{axis}RATE_MAX"])
        base = P_RATE_PID + i * RATE_PID_SIZE
        P[base:base + 4] = [v[f"MC_{axis}RATE_{n}"] for n in ("P", "I", "D", "K")]
        P[base + 4] = plant[i]
    P[P_DCUT] = v["IMU_DGYRO_CUTOFF"]
    P[P_DRAG], P[P_YAW_DAMPING] = drag, yaw_damping
    return P


def initial_state(position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                  yaw: float, yaw_rate: float, hover: float) -> np.ndarray:
    """The loop in steady flight on a reference.

    Parameters
    ----------
    position, velocity, acceleration, yaw, yaw_rate, hover
        As for `mavsysid.vehicle.arducopter_loop.initial_state` (hover: ``MPC_THR_HOVER``).
    """
    s = np.zeros(STATE_SIZE)
    s[S_TP:S_TP + 3] = s[S_P:S_P + 3] = position
    s[S_TV:S_TV + 3] = s[S_V:S_V + 3] = velocity
    s[S_TA:S_TA + 3] = s[S_ACC:S_ACC + 3] = s[S_ACC_T:S_ACC_T + 3] = acceleration
    s[S_TYAW], s[S_TYAW_RATE] = yaw, yaw_rate
    q = _attitude_setpoint(acceleration[0], acceleration[1], yaw)
    s[S_Q:S_Q + 4] = s[S_QD:S_QD + 4] = q
    rate = yaw_rate * rotate_inverse_tuple(q, (0.0, 0.0, 1.0))[2]
    s[S_W + 2] = s[S_RATE_T + 2] = s[S_RPID + 8] = rate
    s[S_THRUST] = (GRAVITY + acceleration[2]) / max(rotate_tuple(q, (0.0, 0.0, 1.0))[2], 0.1)
    return s


@numba.njit(cache=True)
def _attitude_setpoint(ax, ay, yaw):
    """Body z along (ax, ay, g), x_B perpendicular to the heading's y axis."""
    n = math.sqrt(ax * ax + ay * ay + GRAVITY * GRAVITY)
    zx, zy, zz = ax / n, ay / n, GRAVITY / n
    cx, cy = -math.sin(yaw), math.cos(yaw)               # y_C
    xx, xy, xz = cy * zz, -cx * zz, cx * zy - cy * zx    # y_C × z_B
    m = math.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / m, xy / m, xz / m
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    return matrix_to_quat_tuple(((xx, yx, zx), (xy, yy, zy), (xz, yz, zz)))


@numba.njit(cache=True)
def _tilt_limited(ax, ay, tilt_max):
    """The horizontal acceleration whose thrust direction is at most ``tilt_max`` from up."""
    return limit_length(ax, ay, GRAVITY * math.tan(tilt_max))


@numba.njit(cache=True)
def _position(P, s, dt):
    """Position P and velocity PID → acceleration target, attitude setpoint and thrust."""
    vx = s[S_TV] + P[P_XY_P] * (s[S_TP] - s[S_P])
    vy = s[S_TV + 1] + P[P_XY_P] * (s[S_TP + 1] - s[S_P + 1])
    vx, vy = limit_length(vx, vy, P[P_VXY_MAX])
    vz = clamp(s[S_TV + 2] + P[P_Z_P] * (s[S_TP + 2] - s[S_P + 2]), -P[P_VDN], P[P_VUP])
    errors = (vx - s[S_V], vy - s[S_V + 1], vz - s[S_V + 2])
    for i in range(3):
        kp, ki, kd = ((P[P_VXY_P], P[P_VXY_I], P[P_VXY_D]) if i < 2
                      else (P[P_VZ_P], P[P_VZ_I], P[P_VZ_D]))
        s[S_ACC_T + i] = (s[S_TA + i] + kp * errors[i] + s[S_VI + i]
                          - kd * s[S_ACC + i])
        s[S_VI + i] += ki * errors[i] * dt
    s[S_VI + 2] = clamp(s[S_VI + 2], -GRAVITY, GRAVITY)
    ax, ay = _tilt_limited(s[S_ACC_T], s[S_ACC_T + 1], P[P_TILT])
    q = _attitude_setpoint(ax, ay, s[S_TYAW])
    for i in range(4):
        s[S_QD + i] = q[i]
    cos_tilt = GRAVITY / math.sqrt(ax * ax + ay * ay + GRAVITY * GRAVITY)
    s[S_THRUST] = max(GRAVITY + s[S_ACC_T + 2], 0.1 * GRAVITY) / cos_tilt


@numba.njit(cache=True)
def _attitude(P, s):
    """Tilt first, yaw weighted: the body-rate setpoint, yaw rate fed forward."""
    q = (s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3])
    qd = (s[S_QD], s[S_QD + 1], s[S_QD + 2], s[S_QD + 3])
    ez = rotate_tuple(q, (0.0, 0.0, 1.0))
    ezd = rotate_tuple(qd, (0.0, 0.0, 1.0))
    cx, cy, cz = ez[1] * ezd[2] - ez[2] * ezd[1], ez[2] * ezd[0] - ez[0] * ezd[2], \
        ez[0] * ezd[1] - ez[1] * ezd[0]
    dot = ez[0] * ezd[0] + ez[1] * ezd[1] + ez[2] * ezd[2]
    red = normalized_tuple((1.0 + dot, cx, cy, cz))
    red = multiply_tuple(red, q)
    # The rest is a turn about z: its angle, the shorter way, weighted.
    angle = log_tuple(multiply_tuple(conjugate_tuple(red), qd))[2] * P[P_YAW_W]
    qd = multiply_tuple(red, (math.cos(0.5 * angle), 0.0, 0.0, math.sin(0.5 * angle)))
    qe = multiply_tuple(conjugate_tuple(q), qd)
    sign = -2.0 if qe[0] < 0.0 else 2.0
    yaw_gain = P[P_ATT_P + 2] / P[P_YAW_W] if P[P_YAW_W] > 1e-4 else P[P_ATT_P + 2]
    gains = (P[P_ATT_P], P[P_ATT_P + 1], yaw_gain)
    fx, fy, fz = rotate_inverse_tuple(q, (0.0, 0.0, s[S_TYAW_RATE]))
    ff = (fx, fy, fz)
    for i in range(3):
        rate = sign * qe[1 + i] * gains[i] + ff[i]
        s[S_RATE_T + i] = clamp(rate, -P[P_RATE_MAX + i], P[P_RATE_MAX + i])


@numba.njit(cache=True)
def _rates(P, s, dt):
    """Rate PIDs (D on the filtered measured ω̇) → angular acceleration."""
    alpha = lowpass_alpha(dt, P[P_DCUT])
    for i in range(3):
        g = P_RATE_PID + i * RATE_PID_SIZE
        kp, ki, kd, k = P[g], P[g + 1], P[g + 2], P[g + 3]
        m = S_RPID + 3 * i
        s[m + 1] += alpha * ((s[S_W + i] - s[m + 2]) / dt - s[m + 1])
        s[m + 2] = s[S_W + i]
        error = s[S_RATE_T + i] - s[S_W + i]
        out = clamp(k * (kp * error + s[m] - kd * s[m + 1]), -1.0, 1.0)
        s[m] = clamp(s[m] + k * ki * error * dt, -_INTEGRATOR_LIMIT, _INTEGRATOR_LIMIT)
        s[S_WDOT_MOTOR + i] = P[g + 4] * out


@numba.njit(cache=True)
def _plant(P, s, dt):
    q = (s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3])
    zx, zy, zz = rotate_tuple(q, (0.0, 0.0, 1.0))
    thrust = s[S_THRUST]
    along = s[S_V] * zx + s[S_V + 1] * zy + s[S_V + 2] * zz
    drag = thrust * P[P_DRAG]
    s[S_ACC] = thrust * zx - drag * (s[S_V] - along * zx)
    s[S_ACC + 1] = thrust * zy - drag * (s[S_V + 1] - along * zy)
    s[S_ACC + 2] = thrust * zz - GRAVITY - drag * (s[S_V + 2] - along * zz)
    s[S_WDOT], s[S_WDOT + 1] = s[S_WDOT_MOTOR], s[S_WDOT_MOTOR + 1]
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
        out[row, 21 + i] = s[S_TP + i]
        out[row, 28 + i] = s[S_WDOT_MOTOR + i]
    for i in range(4):
        out[row, 10 + i] = s[S_Q + i]
        out[row, 24 + i] = s[S_QD + i]
    out[row, 20] = s[S_THRUST]


@numba.njit(cache=True)
def run_loop(P, setpoints, s, ticks, record_every, out):
    """Fly ``ticks`` ticks of ``P[P_DT]`` s from state ``s`` (updated in place).

    Parameters
    ----------
    P, setpoints, s, ticks, record_every, out
        As for `mavsysid.vehicle.arducopter_loop.run_loop` (this module's layouts).
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
        _position(P, s, dt)
        _attitude(P, s)
        _rates(P, s, dt)
        _plant(P, s, dt)
