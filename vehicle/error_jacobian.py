"""The Jacobians A and G of the error-state dynamics, as a numba kernel (paper Eq. prior).

The error state and its conventions are those of `mavsysid.vehicle.linearization`
(which re-exports `jacobian_kernel`): δx = [δp, δv_B, δφ, δω, δθ̃], 18 entries, the
attitude error in the body frame and θ in scaled units. The nominal ω̇ that the
derivatives by the inertia need comes from the shared laws of `mavsysid.vehicle.mav_model`.
"""

from __future__ import annotations

import numba
import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import add_rotor_wrench, euler_kernel, rotor_thrust_kernel
from mavsysid.vehicle.rotation import rotation_kernel

__all__ = ["jacobian_kernel"]


@numba.njit(cache=True)
def _skew_into(v, out):
    out[0, 0] = 0.0
    out[0, 1] = -v[2]
    out[0, 2] = v[1]
    out[1, 0] = v[2]
    out[1, 1] = 0.0
    out[1, 2] = -v[0]
    out[2, 0] = -v[1]
    out[2, 1] = v[0]
    out[2, 2] = 0.0


@numba.njit(cache=True)
def _rotor_sums(n, c_T, c_D, r, eps, v, w):
    """Sums over the rotors of paper Eq. drag and its derivatives, for the Jacobian.

    Returns Σ T_i, Σ ε_i n_i², Σ T_i r_i, ∂F/∂c_T, ∂F/∂c_D, ∂M/∂c_T, ∂M/∂c_D and
    Σ T_i [r_i]× D [r_i]× (the rotor-drag part of ∂M/∂ω, divided by c_D).
    """
    sum_T = 0.0
    sum_eps_n2 = 0.0
    Tr = np.zeros(3)
    dF_dcT = np.zeros(3)
    dF_dcD = np.zeros(3)
    dM_dcT = np.zeros(3)
    dM_dcD = np.zeros(3)
    dM_dw = np.zeros((3, 3))
    rx = np.empty((3, 3))
    for i in range(n.shape[0]):
        n2 = n[i] * n[i]
        T = rotor_thrust_kernel(c_T, n[i])
        ri = r[i]
        hub = v + np.cross(w, ri)  # v_B + ω × r_i (paper Eq. drag)
        a = np.array([-c_D * n2 * hub[0], -c_D * n2 * hub[1], n2])  # ∂F_i/∂c_T
        b = np.array([-T * hub[0], -T * hub[1], 0.0])  # ∂F_i/∂c_D
        dM_dcT += np.cross(ri, a)
        dM_dcD += np.cross(ri, b)
        dF_dcT += a
        dF_dcD += b
        sum_T += T
        sum_eps_n2 += eps[i] * n2
        Tr += T * ri
        _skew_into(ri, rx)
        # Σ T_i [r_i]× D [r_i]×, with D = diag(1, 1, 0) zeroing the third column of [r_i]×.
        for p in range(3):
            for q in range(3):
                dM_dw[p, q] += T * (rx[p, 0] * rx[0, q] + rx[p, 1] * rx[1, q])
    return sum_T, sum_eps_n2, Tr, dF_dcT, dF_dcD, dM_dcT, dM_dcD, dM_dw


@numba.njit(cache=True)
def _translation_rows(A, R, v, w, c_D, mass, sum_T, Tr, dF_dcT, dF_dcD):
    """Rows of δṗ, δv̇ and δφ̇ (position, paper Eq. newton, attitude kinematics)."""
    sk = np.empty((3, 3))
    rx = np.empty((3, 3))
    # ṗ = R v_B with R = R̂ (I + [δφ]×)
    _skew_into(v, sk)
    A[0:3, 3:6] = R
    A[0:3, 6:9] = -(R @ sk)
    # Paper Eq. newton
    _skew_into(w, sk)
    for p in range(3):
        for q in range(3):
            A[3 + p, 3 + q] = -sk[p, q]
    A[3, 3] -= c_D * sum_T / mass
    A[4, 4] -= c_D * sum_T / mass
    g_body = -GRAVITY * R[2, :]  # Rᵀ g
    _skew_into(g_body, sk)
    A[3:6, 6:9] = sk
    _skew_into(Tr, rx)
    _skew_into(v, sk)
    for q in range(3):  # ∂F/∂ω = c_D D [Σ T_i r_i]×, plus [v]× from -ω × v
        A[3, 9 + q] = c_D * rx[0, q] / mass + sk[0, q]
        A[4, 9 + q] = c_D * rx[1, q] / mass + sk[1, q]
        A[5, 9 + q] = sk[2, q]
    A[3:6, 12] = dF_dcT / mass
    A[3:6, 13] = dF_dcD / mass
    # Attitude error kinematics: δφ̇ = -ω × δφ + δω
    _skew_into(w, sk)
    for p in range(3):
        for q in range(3):
            A[6 + p, 6 + q] = -sk[p, q]
        A[6 + p, 9 + p] = 1.0


@numba.njit(cache=True)
def _rotation_rows(A, w, J, w_dot, c_D, Tr, dM_dw, dM_dcT, dM_dcD, sum_eps_n2):
    """Rows of δω̇ (paper Eq. euler) at the nominal ω̇ ``w_dot``."""
    sk = np.empty((3, 3))
    rx = np.empty((3, 3))
    _skew_into(Tr, rx)
    for p in range(3):
        for q in range(2):  # ∂M/∂v = -c_D [Σ T_i r_i]× D
            A[9 + p, 3 + q] = -c_D * rx[p, q] / J[p]
    # ∂(ω × J ω)/∂ω = [ω]× J - [J ω]×
    wx = np.empty((3, 3))
    _skew_into(w, wx)
    _skew_into(J * w, sk)
    for p in range(3):
        for q in range(3):
            A[9 + p, 9 + q] = (c_D * dM_dw[p, q] - wx[p, q] * J[q] + sk[p, q]) / J[p]
    A[9:12, 12] = dM_dcT / J
    A[9:12, 13] = dM_dcD / J
    A[11, 14] = -sum_eps_n2 / J[2]
    for a_ in range(3):
        e_a = np.zeros(3)
        e_a[a_] = 1.0
        col = -np.cross(w, e_a) * w[a_] / J
        col[a_] -= w_dot[a_] / J[a_]
        A[9:12, 15 + a_] = col


@numba.njit(cache=True)
def jacobian_kernel(x, n, theta, mass, r, eps, scale, A, G):
    """A (18, 18) and G (18, 6) of one state into ``A`` and ``G``; see `ErrorStateModel`.

    Parameters
    ----------
    x : ndarray, shape (13,)
        State [p, v_B, q, ω].
    n : ndarray, shape (k,)
        Rotor speeds, rad/s.
    theta : ndarray, shape (P,)
        Quantities, SI: the paper's θ first (the only ones read here).
    mass : float
        kg.
    r : ndarray, shape (k, 3)
        Rotor positions, m, body FLU.
    eps : ndarray, shape (k,)
        Rotor directions ±1.
    scale : ndarray, shape (P,)
        Units of the quantities' error states (`ErrorStateModel.theta_scale`).
    A : ndarray, shape (12 + P, 12 + P)
        Receives ∂ẋ/∂δx; the columns of nuisance quantities stay 0 here
        (`mavsysid.vehicle.linearization.extra_columns_kernel` fills them).
    G : ndarray, shape (12 + P, 6)
        Receives the process-noise input matrix.
    """
    c_D = theta[1]
    J = theta[3:6]
    v = x[3:6]
    w = x[10:13]
    A[:] = 0.0
    G[:] = 0.0
    sum_T, sum_eps_n2, Tr, dF_dcT, dF_dcD, dM_dcT, dM_dcD, dM_dw = _rotor_sums(
        n, theta[0], c_D, r, eps, v, w)
    # The nominal ω̇ (paper Eq. euler), which the derivatives by J need.
    force = np.zeros(3)
    torque = np.zeros(3)
    add_rotor_wrench(n, theta, r, eps, v, w, force, torque)
    w_dot = np.empty(3)
    euler_kernel(torque, w, J, w_dot)
    _translation_rows(A, rotation_kernel(x[6:10]), v, w, c_D, mass, sum_T, Tr, dF_dcT,
                      dF_dcD)
    _rotation_rows(A, w, J, w_dot, c_D, Tr, dM_dw, dM_dcT, dM_dcD, sum_eps_n2)
    for q in range(6):
        A[:, 12 + q] *= scale[q]
    for p in range(3):
        G[3 + p, p] = 1.0 / mass
        G[9 + p, 3 + p] = 1.0 / J[p]
