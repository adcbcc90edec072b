"""Belief propagation along edges (paper Section "Belief Propagation").

Along a candidate segment the nominal flat states are sampled at the estimator's
measurement rate, the full state and rotor speeds are recovered by flatness, the model
is linearised with the shared `mavsysid.vehicle.linearization` kernels, and the EKF covariance
recursion, whose every step is the estimator's own (`mavsysid.vehicle.covariance`), is
collapsed into one transfer (paper Eq. one_step, after Prentice & Roy):

    S_k^C = (F_k, Q_k; 0, F_kᵀ),   S_k^M = (I, 0; -Hᵀ R⁻¹ H, I),
    S_k = S_k^C ⋆ S_k^M,           S_edge = S_1 ⋆ S_2 ⋆ … ⋆ S_K,

with ⋆ the Redheffer star product. A belief Σ then crosses the edge in one step: Σ' is
the upper-right block of (I, Σ; 0, I) ⋆ S_edge = B + A Σ (I - C Σ)⁻¹ D.

Measurement ownership: an edge of duration T is cut into K = round(T · rate) steps; it
owns the measurements at the end of each step (its interior samples and its end vertex),
never the one at its start. Chained edges therefore count a shared vertex once, as the
estimator sees it once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.vehicle.autopilot_loop import AutopilotLoop, FlownFlight, fly
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.covariance import (
    measurement_information,
    predict_covariance_kernel,
    update_covariance_kernel,
)
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.linearization import E_THETA, ErrorStateModel
from mavsysid.vehicle.trajectory import FlatOutputs, Trajectory

__all__ = [
    "EdgeTransfer",
    "apply_transfer",
    "apply_transfer_logdet",
    "edge_samples",
    "edge_transfer",
    "flown_samples",
    "flown_steps",
    "identity_transfer",
    "propagate_final",
    "propagate_steps",
    "riccati_final",
    "segments_samples",
    "star",
    "steps_transfer",
]


@dataclass(frozen=True)
class EdgeTransfer:
    """The one-step transfer S = (A, B; C, D) of an edge, each block (D, D) of the error
    state (`ErrorStateModel.dim`)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray


def identity_transfer(dim: int = E_THETA.stop) -> EdgeTransfer:
    """The transfer of an empty edge: (I, 0; 0, I).

    Parameters
    ----------
    dim : int
        Length of the error state (`ErrorStateModel.dim`; the paper's model's by default).
    """
    eye, zero = np.eye(dim), np.zeros((dim, dim))
    return EdgeTransfer(eye, zero, zero.copy(), eye.copy())


@numba.njit(cache=True)
def _star_kernel(A1, B1, C1, D1, A2, B2, C2, D2):
    """Redheffer star product S1 ⋆ S2 of 2×2 block operators S = (A, B; C, D).

    S1 ⋆ S2 = (A2 (I − B1 C2)⁻¹ A1,           B2 + A2 B1 (I − C2 B1)⁻¹ D2;
               C1 + D1 C2 (I − B1 C2)⁻¹ A1,   D1 (I − C2 B1)⁻¹ D2),
    the product under which (I, Σ; 0, I) ⋆ (F, Q; 0, Fᵀ) carries Σ' = F Σ Fᵀ + Q and
    (I, Σ; 0, I) ⋆ (I, 0; −HᵀR⁻¹H, I) carries Σ' = (Σ⁻¹ + HᵀR⁻¹H)⁻¹ (paper Eq. one_step).
    """
    eye = np.eye(A1.shape[0])
    M1 = eye - B1 @ C2
    M2 = eye - C2 @ B1
    X = np.linalg.solve(M1, A1)  # (I - B1 C2)⁻¹ A1
    Y = np.linalg.solve(M2, D2)  # (I - C2 B1)⁻¹ D2
    return A2 @ X, B2 + A2 @ B1 @ Y, C1 + D1 @ C2 @ X, D1 @ Y


def star(s1: EdgeTransfer, s2: EdgeTransfer) -> EdgeTransfer:
    """S1 ⋆ S2: first s1, then s2 (paper Eq. one_step)."""
    return EdgeTransfer(*_star_kernel(s1.A, s1.B, s1.C, s1.D, s2.A, s2.B, s2.C, s2.D))


@numba.njit(cache=True)
def _chain_kernel(F, Q, HRH):
    """S_1 ⋆ … ⋆ S_K with S_k = (F_k, Q_k; 0, F_kᵀ) ⋆ (I, 0; -HRH, I)."""
    n = F.shape[1]
    eye = np.eye(n)
    zero = np.zeros((n, n))
    A, B, C, D = eye.copy(), zero.copy(), zero.copy(), eye.copy()
    for k in range(F.shape[0]):
        # S^C ⋆ S^M in closed form: (I + Q HRH)⁻¹ F, (I + Q HRH)⁻¹ Q, -Fᵀ HRH (I + Q HRH)⁻¹ F,
        # Fᵀ (I + HRH Q)⁻¹ — from the star formula with B1 = Q, C2 = -HRH.
        Mq = eye + Q[k] @ HRH
        Ak = np.linalg.solve(Mq, F[k])
        Bk = np.linalg.solve(Mq, Q[k])
        Ck = -F[k].T @ HRH @ Ak
        Dk = F[k].T @ np.linalg.solve(eye + HRH @ Q[k], eye)
        A, B, C, D = _star_kernel(A, B, C, D, Ak, Bk, Ck, Dk)
    return A, B, C, D


@numba.njit(cache=True)
def _apply_kernel(Sigma, A, B, C, D):
    n = Sigma.shape[0]
    out = B + A @ Sigma @ np.linalg.solve(np.eye(n) - C @ Sigma, D)
    return 0.5 * (out + out.T)


@numba.njit(cache=True)
def _apply_logdet_kernel(Sigma, A, B, C, D, theta_start):
    out = _apply_kernel(Sigma, A, B, C, D)
    L = np.linalg.cholesky(out)
    full = 2.0 * np.sum(np.log(np.diag(L)))
    Lt = np.linalg.cholesky(out[theta_start:, theta_start:])
    return out, full, 2.0 * np.sum(np.log(np.diag(Lt)))


def apply_transfer_logdet(
    sigma: np.ndarray, transfer: EdgeTransfer, theta_start: int = 12
) -> tuple[np.ndarray, float, float]:
    """`apply_transfer` plus log det of Σ' and of its θ block (one compiled call)."""
    return _apply_logdet_kernel(np.ascontiguousarray(sigma), transfer.A, transfer.B,
                                transfer.C, transfer.D, theta_start)


def apply_transfer(sigma: np.ndarray, transfer: EdgeTransfer) -> np.ndarray:
    """Σ' = B + A Σ (I - C Σ)⁻¹ D: a belief across an edge in one step, shape (18, 18)."""
    return _apply_kernel(np.ascontiguousarray(sigma), transfer.A, transfer.B, transfer.C,
                         transfer.D)


def edge_samples(
    trajectory: Trajectory, config: VehicleConfig, theta: np.ndarray, rate: float,
    autopilot: AutopilotLoop | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Nominal states and rotor speeds at the K + 1 step boundaries of a segment.

    Parameters
    ----------
    trajectory : Trajectory
        The segment (flat outputs over its duration).
    config : VehicleConfig
    theta : ndarray, shape (6,)
        θ of the flatness map (or of the autopilot's plant), SI.
    rate : float
        Steps per second, Hz.
    autopilot : AutopilotLoop, optional
        The closed loop that flies the segment (`flown_samples`); None: the setpoints are
        flown exactly (the flatness map, the paper's assumption).

    Returns
    -------
    states : ndarray, shape (K + 1, 13)
    rotor_speeds : ndarray, shape (K + 1, k)
    dt : float
        Step, s (T / K with K = max(1, round(T · rate))).
    """
    if autopilot is not None:
        return flown_samples(trajectory, config, theta, rate, autopilot)
    T = trajectory.duration
    K = max(1, round(T * rate))
    tau = np.linspace(0.0, T, K + 1)
    flat = flat_to_state(trajectory.flat_outputs(tau), config, theta)
    return flat.states(), flat.rotor_speeds, T / K


def flown_samples(
    trajectory: Trajectory, config: VehicleConfig, theta: np.ndarray, rate: float,
    autopilot: AutopilotLoop,
) -> tuple[np.ndarray, np.ndarray, float]:
    """`edge_samples` of the flight ``autopilot`` flies when the segment is streamed to it
    (`mavsysid.vehicle.autopilot_loop.fly`), from steady flight on the segment's start.

    Parameters
    ----------
    trajectory, config, theta, rate
        As for `edge_samples`.
    autopilot : AutopilotLoop
        The autopilot's closed loop.

    Returns
    -------
    states : ndarray, shape (K + 1, 13)
    rotor_speeds : ndarray, shape (K + 1, k)
        The rotor speeds of the predicted thrust and rotor torques.
    dt : float
    """
    flight, dt = flown_steps(trajectory, config, theta, rate, autopilot)
    return flight.states(), flight.rotor_speeds, dt


def flown_steps(
    trajectory: Trajectory, config: VehicleConfig, theta: np.ndarray, rate: float,
    autopilot: AutopilotLoop,
) -> tuple[FlownFlight, float]:
    """The predicted flight of `flown_samples` itself (K + 1 samples) and its step, s.

    Parameters
    ----------
    trajectory, config, theta, rate, autopilot
        As for `flown_samples`.
    """
    T = trajectory.duration
    K = max(1, round(T * rate))
    return fly(autopilot, trajectory, config, theta, sample_step=T / K), T / K


def segments_samples(
    segments: list, config: VehicleConfig, theta: np.ndarray, rate: float,
    autopilot: AutopilotLoop | None = None,
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """`edge_samples` of several segments with one flatness call (its overhead dominates).

    Parameters
    ----------
    segments : list of mavsysid.planner.segments.Segment
        Segments (any object with ``duration`` and ``flat_outputs(tau)``).
    config, theta, rate, autopilot
        As for `edge_samples` (with an autopilot, each segment is flown on its own).

    Returns
    -------
    list of (states (K + 1, 13), rotor_speeds (K + 1, k), dt s), one per segment
    """
    if autopilot is not None:
        return [flown_samples(s, config, theta, rate, autopilot) for s in segments]
    flats, counts, steps = [], [], []
    for segment in segments:
        T = segment.duration
        K = max(1, round(T * rate))
        flats.append(segment.flat_outputs(np.linspace(0.0, T, K + 1)))
        counts.append(K + 1)
        steps.append(T / K)
    fields = FlatOutputs.__dataclass_fields__
    joined = FlatOutputs(**{f: np.concatenate([getattr(x, f) for x in flats]) for f in fields})
    flat = flat_to_state(joined, config, theta)
    states, speeds = flat.states(), flat.rotor_speeds
    out, start = [], 0
    for count, dt in zip(counts, steps, strict=True):
        out.append((states[start:start + count], speeds[start:start + count], dt))
        start += count
    return out


@numba.njit(cache=True)
def _riccati_kernel(P, F, Q, R, history):
    """The EKF covariance recursion over the steps of F and Q, from P (updated in place).

    Each step is the estimator's own (paper Eqs. prior–posterior, `predict_covariance_kernel`
    and `update_covariance_kernel`). ``history`` (K + 1, 18, 18) receives P after each step
    at rows 1…K; pass shape (0, 18, 18) for the final P only.
    """
    S = np.empty((R.shape[0], R.shape[0]))
    SI = np.empty_like(S)
    K = np.empty((P.shape[0], R.shape[0]))
    for k in range(F.shape[0]):
        predict_covariance_kernel(P, F[k], Q[k])
        update_covariance_kernel(P, R, S, SI, K)
        if history.shape[0] > 0:
            history[k + 1] = P


def riccati_final(model: ErrorStateModel, sigma0: np.ndarray, F: np.ndarray,
                  Q: np.ndarray) -> np.ndarray:
    """`propagate_steps`' final covariance from the steps' F and Q, compiled, (D, D).

    For one known starting belief this is several times cheaper than building the
    edge's transfer and applying it; the refinement prices each candidate segment this
    way and builds transfers (`steps_transfer`, same F and Q) only for the ones it keeps.
    """
    P = np.array(sigma0, dtype=float)
    _riccati_kernel(P, F, Q, model.measurement_covariance(),
                    np.empty((0, model.dim, model.dim)))
    return P


def propagate_final(
    model: ErrorStateModel, sigma0: np.ndarray, states: np.ndarray, rotor_speeds: np.ndarray,
    theta: np.ndarray, dt: float,
) -> np.ndarray:
    """`riccati_final` along samples as returned by `edge_samples`, shape (D, D)."""
    F, Q = model.discrete(states[:-1], rotor_speeds[:-1], theta, dt)
    return riccati_final(model, sigma0, F, Q)


def edge_transfer(
    model: ErrorStateModel, states: np.ndarray, rotor_speeds: np.ndarray, theta: np.ndarray,
    dt: float,
) -> EdgeTransfer:
    """The transfer of an edge sampled as by `edge_samples` (measurements at steps 1…K).

    Step k predicts from sample k-1 (linearised there, like the EKF) and then takes the
    measurement at sample k.
    """
    F, Q = model.discrete(states[:-1], rotor_speeds[:-1], theta, dt)
    return steps_transfer(model, F, Q)


def steps_transfer(model: ErrorStateModel, F: np.ndarray, Q: np.ndarray) -> EdgeTransfer:
    """The transfer of K steps with transitions F and process noises Q, each (K, D, D)."""
    information = measurement_information(model.measurement_covariance(), model.dim)
    return EdgeTransfer(*_chain_kernel(F, Q, information))


def propagate_steps(
    model: ErrorStateModel, sigma0: np.ndarray, states: np.ndarray, rotor_speeds: np.ndarray,
    theta: np.ndarray, dt: float,
) -> np.ndarray:
    """Step-by-step EKF covariance (paper Eqs. prior–posterior) along samples, (K + 1, D, D).

    The reference the star-product transfer is checked against, and the predicted σ over
    time of a chosen path.
    """
    F, Q = model.discrete(states[:-1], rotor_speeds[:-1], theta, dt)
    out = np.empty((F.shape[0] + 1, model.dim, model.dim))
    out[0] = sigma0
    _riccati_kernel(np.array(sigma0, dtype=float), F, Q, model.measurement_covariance(), out)
    return out
