"""The EKF covariance step and the pose measurement, shared by the planner and the estimator.

The planner's belief is the estimator's covariance (paper Section "Belief Propagation"),
so both take the step from here: the prediction P ← F P Fᵀ + Q (paper Eq. prior) and
the Joseph-form measurement update (paper Eqs. S_k, K_k, posterior) are numba kernels
called by the parameter EKF (`mavsysid.estimation.filter.ekf`), by the planner's step-by-step
recursion and its star-product transfer (`mavsysid.planner.belief`) and, for the
process noise accumulated between shooting nodes, by the batch refinement
(`mavsysid.estimation.batch.kernels`).

The measurement is a motion-capture pose, z = [p (3), q (4)], with
``q_meas = q ⊗ Exp(φ)`` (paper measurement model). Its residual is
[p_meas − p̂, Log(q̂⁻¹ ⊗ q_meas)] (`pose_residual_kernel`), which depends on the error
state δx (D,) of `mavsysid.vehicle.linearization` through δp and δφ with unit gain:
H (6, D) selects the entries `MEASURED_ERROR_INDICES`. The update kernel uses that H
is a selection, reading P Hᵀ and H P Hᵀ off P instead of multiplying.
"""

from __future__ import annotations

import numba
import numpy as np
from mavsysid.vehicle.linearization import E_ATT, E_POS, MEAS_DIM
from mavsysid.vehicle.rotation import log_kernel, multiply_kernel

__all__ = [
    "MEASURED_ERROR_INDICES",
    "measurement_information",
    "measurement_matrix",
    "pose_residual_kernel",
    "predict_covariance_kernel",
    "update_covariance_kernel",
]

#: Error-state entries the pose measurement observes, in residual order: δp, then δφ.
MEASURED_ERROR_INDICES = np.r_[E_POS, E_ATT]


def measurement_matrix(dim: int) -> np.ndarray:
    """H, shape (6, D): the pose residual's derivative by the error state (unit gain).

    Parameters
    ----------
    dim : int
        D, the length of the error state (`ErrorStateModel.dim`).

    Returns
    -------
    ndarray, shape (6, D)
        Row i has a one in column ``MEASURED_ERROR_INDICES[i]``, zeros elsewhere.
    """
    H = np.zeros((MEAS_DIM, dim))
    H[np.arange(MEAS_DIM), MEASURED_ERROR_INDICES] = 1.0
    return H


def measurement_information(R: np.ndarray, dim: int) -> np.ndarray:
    """Hᵀ R⁻¹ H, shape (D, D): the information one pose measurement adds.

    Parameters
    ----------
    R : ndarray, shape (6, 6)
        Measurement noise covariance, m² and rad² (position first).
    dim : int
        D, the length of the error state.

    Returns
    -------
    ndarray, shape (D, D)
        R⁻¹ placed at the measured rows and columns, zeros elsewhere (paper Eq. one_step,
        the measurement transfer S_k^M).
    """
    H = measurement_matrix(dim)
    return H.T @ np.linalg.solve(np.asarray(R, dtype=float), H)


@numba.njit(cache=True)
def pose_residual_kernel(z, x, out):
    """The pose residual [p_meas − p̂, Log(q̂⁻¹ ⊗ q_meas)] into ``out`` (6,).

    Parameters
    ----------
    z : ndarray, shape (7,)
        Measured pose [p (m), q (unit quaternion w, x, y, z)].
    x : ndarray, shape (≥ 10,)
        Nominal state; p̂ = x[0:3], q̂ = x[6:10].
    out : ndarray, shape (6,)
        Receives the residual, m and rad (body-frame attitude error).
    """
    out[0:3] = z[0:3] - x[0:3]
    conj = np.array([x[6], -x[7], -x[8], -x[9]])
    out[3:6] = log_kernel(multiply_kernel(conj, z[3:7]))


_MEASURED = MEASURED_ERROR_INDICES  # a global array: numba compiles it in as a constant


@numba.njit(cache=True)
def _symmetrise(P):
    """P ← ½ (P + Pᵀ) in place, without temporaries (the same values as the expression)."""
    for i in range(P.shape[0]):
        for j in range(i + 1, P.shape[0]):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@numba.njit(cache=True)
def predict_covariance_kernel(P, F, Q):
    """Paper Eq. prior: P ← F P Fᵀ + Q, symmetrised, in place.

    Parameters
    ----------
    P : ndarray, shape (n, n)
        Covariance of the error state at the step's start; receives the prediction.
    F : ndarray, shape (n, n)
        Transition over the step.
    Q : ndarray, shape (n, n)
        Process noise accumulated over the step.
    """
    P[:] = F @ P @ F.T + Q
    _symmetrise(P)


@numba.njit(cache=True)
def update_covariance_kernel(P, R, S, SI, K):
    """Paper Eqs. S_k, K_k, posterior for one pose measurement, Joseph form, in place.

    S = H P Hᵀ + R and K = P Hᵀ S⁻¹ from the predicted P, then
    P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ, symmetrised. H selects
    `MEASURED_ERROR_INDICES`, so P Hᵀ is columns of P and H P Hᵀ a block of it.

    Parameters
    ----------
    P : ndarray, shape (D, D)
        Predicted error-state covariance; receives the posterior.
    R : ndarray, shape (6, 6)
        Measurement noise covariance, m² and rad².
    S, SI : ndarray, shape (6, 6)
        Receive the innovation covariance and its inverse.
    K : ndarray, shape (D, 6)
        Receives the Kalman gain.
    """
    n = P.shape[0]
    m = _MEASURED.shape[0]
    PHT = np.empty((n, m))
    for j in range(m):
        PHT[:, j] = P[:, _MEASURED[j]]
    for i in range(m):
        for j in range(m):
            S[i, j] = PHT[_MEASURED[i], j] + R[i, j]
    SI[:] = np.linalg.inv(S)
    K[:] = PHT @ SI
    IKH = np.eye(n)
    for j in range(m):
        IKH[:, _MEASURED[j]] -= K[:, j]
    P[:] = IKH @ P @ IKH.T + K @ R @ K.T
    _symmetrise(P)
