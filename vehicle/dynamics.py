"""Continuous multirotor dynamics ẋ = f(x, u, θ) — the paper's Section "MAV Model".

State x, shape (13,): position p (world ENU, m), velocity v_B (body FLU, m/s),
attitude q (``[w, x, y, z]``, body → world), body rates ω (rad/s). Input u = n, the k
rotor speeds (rad/s). Parameters θ = [c_T, c_D, c_M, j_x, j_y, j_z].

In docs/architecture.md's conventions (gravity g = [0, 0, -9.81], R = R(q) body → world):

    ṗ   = R v_B                                  (paper: position kinematics)
    v̇_B = F_B / m - ω × v_B + Rᵀ g               (paper Eq. newton)
    q̇   = ½ q ⊗ [0, ω]                           (paper: attitude kinematics)
    ω̇   = J⁻¹ (M_B - ω × J ω)                     (paper Eq. euler)

with F_B = Σ F_i + F_ext, M_B = Σ (M_i + r_i × F_i) + M_ext, and per rotor
F_i = c_T n_i² e_z - c_T n_i² diag(c_D, c_D, 0)(v_B + ω × r_i)  (paper Eq. drag),
M_i = -ε_i c_M n_i² e_z. F_ext, M_ext are extra body-frame force and torque: zero in the
model, the hook through which the simulator's truth side adds unmodelled effects.

The rotor wrench and Euler's equation are those of `mavsysid.vehicle.mav_model` (one
statement of each law). The kernel is compiled with numba because the simulator calls
it at ≥ 1 kHz; the numpy-facing `state_derivative` wraps it for arrays of states.

The model is integrated by one RK4 step, `rk4_step_kernel`, given the rotor speeds and
extra wrench at its four stages. The parameter EKF's prediction and the batch
refinement's shooting hold the logged inputs linear over a step
(`rk4_linear_step_kernel`); the simulator's truth hands it the RK4 stages of its lagged
rotor speeds (`mavsysid.flight.offline.truth_step`). So the filter, the refinement and the
simulated truth integrate the rigid body with the same arithmetic.
"""

from __future__ import annotations

import numba
import numpy as np
from mavsysid.vehicle.config_types import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import add_rotor_wrench, euler_kernel
from mavsysid.vehicle.rotation import rotation_kernel

__all__ = [
    "ATT",
    "POS",
    "RATE",
    "STATE_DIM",
    "VEL",
    "derivative_kernel",
    "hover_state",
    "rk4_linear_step_kernel",
    "rk4_step_kernel",
    "state_derivative",
]

STATE_DIM = 13
POS = slice(0, 3)
VEL = slice(3, 6)
ATT = slice(6, 10)
RATE = slice(10, 13)


@numba.njit(cache=True, fastmath=False)
def derivative_kernel(x, n, theta, mass, r, eps, force_ext, torque_ext, out):
    """ẋ of one state into ``out`` (13,). Arrays: x (13,), n (k,), θ (6,), r (k, 3), ε (k,).

    Parameters
    ----------
    x : ndarray, shape (13,)
        State [p, v_B, q, ω].
    n : ndarray, shape (k,)
        Rotor speeds, rad/s.
    theta : ndarray, shape (6,)
        θ, SI.
    mass : float
        kg.
    r : ndarray, shape (k, 3)
        Rotor positions, m, body FLU.
    eps : ndarray, shape (k,)
        Rotor directions ±1.
    force_ext, torque_ext : ndarray, shape (3,)
        Extra body force (N) and torque (N·m).
    out : ndarray, shape (13,)
        Receives ẋ.
    """
    vx, vy, vz = x[3], x[4], x[5]
    wx, wy, wz = x[10], x[11], x[12]
    R = rotation_kernel(x[6:10])
    # F_B = F_ext + Σ F_i and M_B = M_ext + Σ (M_i + r_i × F_i) (paper Eq. drag).
    force = force_ext.copy()
    torque = torque_ext.copy()
    add_rotor_wrench(n, theta, r, eps, x[3:6], x[10:13], force, torque)

    # ṗ = R v_B
    out[0] = R[0, 0] * vx + R[0, 1] * vy + R[0, 2] * vz
    out[1] = R[1, 0] * vx + R[1, 1] * vy + R[1, 2] * vz
    out[2] = R[2, 0] * vx + R[2, 1] * vy + R[2, 2] * vz
    # Paper Eq. newton: v̇_B = F_B/m - ω × v_B + Rᵀ g, g = [0, 0, -GRAVITY].
    out[3] = force[0] / mass - (wy * vz - wz * vy) - GRAVITY * R[2, 0]
    out[4] = force[1] / mass - (wz * vx - wx * vz) - GRAVITY * R[2, 1]
    out[5] = force[2] / mass - (wx * vy - wy * vx) - GRAVITY * R[2, 2]
    # q̇ = ½ q ⊗ [0, ω] on the unnormalised q, so the integrator sees the true field.
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    out[6] = 0.5 * (-qx * wx - qy * wy - qz * wz)
    out[7] = 0.5 * (qw * wx + qy * wz - qz * wy)
    out[8] = 0.5 * (qw * wy + qz * wx - qx * wz)
    out[9] = 0.5 * (qw * wz + qx * wy - qy * wx)
    # Paper Eq. euler: ω̇ = J⁻¹ (M_B - ω × J ω), J = diag(j_x, j_y, j_z).
    euler_kernel(torque, x[10:13], theta[3:6], out[10:13])


@numba.njit(cache=True)
def rk4_step_kernel(x, n_stages, w_stages, theta, dt, mass, r, eps, out):
    """One classical RK4 step of the model state over ``dt``. Compiled (numba, nopython).

    Parameters
    ----------
    x : ndarray, shape (13,)
        Model state [p, v_B, q, ω] at the step's start (m, m/s, unit quaternion, rad/s).
    n_stages : ndarray, shape (4, k)
        Rotor speeds (rad/s) at the four stages: the step's start, its middle (second and
        third stage, which may differ, as for a lagged rotor integrated alongside), its end.
    w_stages : ndarray, shape (4, 6)
        Extra body force and torque [F_B, M_B] (N, N·m) at the four stages; zeros leave
        the model unchanged (0 + F is exact, so the no-effect path is the plain model).
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI.
    dt : float
        Step, s.
    mass : float
        kg.
    r : ndarray, shape (k, 3)
        Rotor positions, m, body frame.
    eps : ndarray, shape (k,)
        Rotor directions, ±1.
    out : ndarray, shape (13,)
        Receives the state at the step's end, its quaternion renormalised.
    """
    # Written out element by element: the simulator takes this step at 1 kHz, and array
    # expressions would allocate a temporary for every stage.
    k = np.empty((4, STATE_DIM))
    stage = np.empty(STATE_DIM)
    derivative_kernel(x, n_stages[0], theta, mass, r, eps, w_stages[0, 0:3], w_stages[0, 3:6],
                      k[0])
    for s in range(1, 4):
        h = dt if s == 3 else 0.5 * dt
        for i in range(STATE_DIM):
            stage[i] = x[i] + h * k[s - 1, i]
        derivative_kernel(stage, n_stages[s], theta, mass, r, eps, w_stages[s, 0:3],
                          w_stages[s, 3:6], k[s])
    for i in range(STATE_DIM):
        out[i] = x[i] + dt / 6.0 * (k[0, i] + 2.0 * k[1, i] + 2.0 * k[2, i] + k[3, i])
    norm = np.sqrt(out[6] * out[6] + out[7] * out[7] + out[8] * out[8] + out[9] * out[9])
    for i in range(6, 10):
        out[i] = out[i] / norm


@numba.njit(cache=True)
def rk4_linear_step_kernel(x, n0, n1, w0, w1, theta, dt, mass, r, eps, out):
    """`rk4_step_kernel` with rotor speeds and wrench linear from the step's start to its end.

    The inputs of a log, known at its samples: the middle stages see their mean.

    Parameters
    ----------
    x : ndarray, shape (13,)
        Model state at the step's start.
    n0, n1 : ndarray, shape (k,)
        Rotor speeds at the step's start and end, rad/s.
    w0, w1 : ndarray, shape (6,)
        Extra body force and torque [F_B, M_B] (N, N·m) at the step's start and end.
    theta, dt, mass, r, eps, out
        As for `rk4_step_kernel`.
    """
    n_stages = np.empty((4, n0.shape[0]))
    w_stages = np.empty((4, 6))
    n_stages[0] = n0
    n_stages[1] = 0.5 * (n0 + n1)
    n_stages[2] = n_stages[1]
    n_stages[3] = n1
    w_stages[0] = w0
    w_stages[1] = 0.5 * (w0 + w1)
    w_stages[2] = w_stages[1]
    w_stages[3] = w1
    rk4_step_kernel(x, n_stages, w_stages, theta, dt, mass, r, eps, out)


@numba.njit(cache=True)
def _derivative_batch(X, N, Theta, mass, r, eps, F_ext, M_ext, out):
    for j in range(X.shape[0]):
        derivative_kernel(X[j], N[j], Theta[j], mass, r, eps, F_ext[j], M_ext[j], out[j])


def state_derivative(
    x: np.ndarray,
    n: np.ndarray,
    config: VehicleConfig,
    theta: np.ndarray | None = None,
    force_ext: np.ndarray | None = None,
    torque_ext: np.ndarray | None = None,
) -> np.ndarray:
    """ẋ = f(x, n, θ) for one state or an array of states.

    Parameters
    ----------
    x : ndarray, shape (..., 13)
        States [p, v_B, q, ω].
    n : ndarray, shape (..., k)
        Rotor speeds, rad/s.
    config : VehicleConfig
        Mass and rotor geometry.
    theta : ndarray, shape (..., 6), optional
        Parameters; the config's nominal θ by default.
    force_ext, torque_ext : ndarray, shape (..., 3), optional
        Extra body-frame force (N) and torque (N·m); zero by default.

    Returns
    -------
    ndarray, shape (..., 13)
        State derivative.
    """
    x = np.asarray(x, dtype=float)
    batch = x.shape[:-1]
    k = config.rotor_count
    theta = config.theta if theta is None else theta
    X = np.ascontiguousarray(x.reshape(-1, STATE_DIM))
    m = X.shape[0]
    N = np.ascontiguousarray(np.broadcast_to(np.asarray(n, dtype=float), (*batch, k)).reshape(m, k))
    Th = np.ascontiguousarray(np.broadcast_to(np.asarray(theta, float), (*batch, 6)).reshape(m, 6))
    zeros = np.zeros(3)
    F = np.broadcast_to(zeros if force_ext is None else np.asarray(force_ext, float), (*batch, 3))
    M = np.broadcast_to(zeros if torque_ext is None else np.asarray(torque_ext, float), (*batch, 3))
    out = np.empty_like(X)
    _derivative_batch(
        X, N, Th, float(config.mass), np.ascontiguousarray(config.rotor_positions),
        np.ascontiguousarray(config.rotor_directions),
        np.ascontiguousarray(F.reshape(m, 3)), np.ascontiguousarray(M.reshape(m, 3)), out,
    )
    return out.reshape(*batch, STATE_DIM)


def hover_state(position: np.ndarray | None = None, yaw: float = 0.0) -> np.ndarray:
    """State at rest, level, at ``position`` (m, world) with yaw (rad), shape (13,).

    Parameters
    ----------
    position : ndarray, shape (3,), optional
        m, world ENU (default: the origin).
    yaw : float
        rad.
    """
    x = np.zeros(STATE_DIM)
    if position is not None:
        x[POS] = position
    x[ATT] = [np.cos(yaw / 2.0), 0.0, 0.0, np.sin(yaw / 2.0)]
    return x
