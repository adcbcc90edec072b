"""θ by equation error: the force and torque balance of the smoothed pose, least squares.

The residual of `mavsysid.estimation.signals` (measured minus model [f_B, ω̇],
both through the same Savitzky–Golay smoother) is driven to zero over θ by Gauss–Newton
with a finite-difference Jacobian (the model is linear in c_T, c_D, c_M and nearly so in
J). Yaw only fixes the ratio c_M / j_z, so the prior (the vehicle file's θ and σ, as in
the filter) is one more observation that sets the scale.

Honest covariance. After smoothing, the residual is correlated over about one smoother
window, so the n rows carry far fewer than n independent observations. The scores
g_i = X_iᵀ e_i (per sample, summed over the six axes, each axis weighted to unit RMS)
give the long-run covariance S by a Newey–West (Bartlett) estimator over two windows
(`statsmodels.stats.sandwich_covariance.S_hac_simple`); the effective-sample factor
κ = tr S / tr Σ g_i g_iᵀ weights the data against the prior, and the reported covariance
is the sandwich A⁻¹ (S/κ² + P⁻¹) A⁻¹ with A = XᵀX/κ + P⁻¹ (scaled units).

The fit is the estimator's robust start (`mavsysid.estimation.filter.guard`) and its independent
check of the final θ: it needs no filter, so it cannot diverge.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from mavsysid.estimation.balance.rows import (
    consistent_accelerations,
    model_accelerations,
)
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.report.figures import uniform_grid
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.estimation.signals import (
    MAX_JITTER,
    SmootherSettings,
    smooth_pose,
)
from mavsysid.vehicle.config import VehicleConfig
from statsmodels.stats.sandwich_covariance import S_hac_simple

from mavsysid.errors import JobFailedError

__all__ = ["EquationErrorFit", "EquationErrorSettings", "fit_equation_error",
           "theta_jacobian"]

#: Relative step of the θ finite differences.
THETA_STEP = 1e-3


@dataclass(frozen=True)
class EquationErrorSettings:
    """Choices of the equation-error fit.

    Attributes
    ----------
    smoother : SmootherSettings
        The Savitzky–Golay smoother (the diagnosis' defaults).
    iterations : int
        Gauss–Newton iterations at most.
    rows_per_window : int
        Rows kept per smoother window: the smoothed residual is band-limited to about one
        window, so denser rows add cost, not information.
    hac_windows : float
        Newey–West lag range, in smoother windows.
    """

    smoother: SmootherSettings = field(default_factory=SmootherSettings)
    iterations: int = 8
    rows_per_window: int = 15
    hac_windows: float = 2.0


@dataclass(frozen=True)
class EquationErrorFit:
    """θ from the force and torque balance.

    Attributes
    ----------
    estimate : ParameterEstimate
        θ (SI) and its HAC covariance, prior included.
    rms : ndarray, shape (6,)
        RMS of the final residual per axis, SI (m/s², rad/s²).
    rows : int
        Rows used.
    effective_rows : float
        rows / κ: the independent observations they are worth.
    """

    estimate: ParameterEstimate
    rms: np.ndarray
    rows: int
    effective_rows: float


def theta_jacobian(residual: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
                   r0: np.ndarray) -> np.ndarray:
    """∂r/∂θ as regressors A (N, 6, 6): r(θ) ≈ r(θ̂) − A Δθ, Δθ in SI.

    Parameters
    ----------
    residual : callable
        θ (6,) → residual (N, 6).
    theta : ndarray, shape (6,)
        θ̂, SI.
    r0 : ndarray, shape (N, 6)
        ``residual(theta)``.
    """
    theta = np.asarray(theta, float)
    cols = np.empty(r0.shape + (6,))
    for j in range(6):
        step = THETA_STEP * (abs(theta[j]) if theta[j] != 0.0 else 1e-3)
        shifted = theta.copy()
        shifted[j] += step
        cols[..., j] = -(residual(shifted) - r0) / step
    return cols


def _uniform_flight(flight: FlightData) -> tuple[np.ndarray, ...]:
    """t, position, quaternion, rotor speeds of the longest segment on a uniform grid."""
    if len(flight.segment_starts) > 1:
        flight = flight.segment(flight.longest_segment())
    dt = np.diff(flight.t)
    step = float(np.median(dt))
    if np.max(np.abs(dt - step)) <= MAX_JITTER * step:
        return flight.t, flight.position, flight.quaternion, flight.rotor_speeds
    t, _, p, q, n = uniform_grid(flight)
    return t, p, q / np.linalg.norm(q, axis=1, keepdims=True), n


def _residual_function(flight: FlightData, config: VehicleConfig,
                       settings: EquationErrorSettings
                       ) -> tuple[Callable[[np.ndarray], np.ndarray], int]:
    """θ → residual on the kept rows, and the rows per smoother window."""
    t, p, q, n = _uniform_flight(flight)
    sm = settings.smoother
    if len(t) < 2 or t[-1] - t[0] < 2.0 * (sm.window + sm.trim) + sm.window:
        raise JobFailedError(f"{flight.source}: {t[-1] - t[0]:.1f} s of pose: too short for "
                             "the equation-error fit")
    pose = smooth_pose(t, p, q, sm, flight.source)
    inputs = smooth_pose(t, p, q, replace(sm, window=sm.input_window), flight.source)
    dt = float(t[1] - t[0])
    window = sm.samples(dt)
    stride = max(1, window // settings.rows_per_window)
    edge = max(sm.trim, window * dt)
    rows = np.flatnonzero((t >= t[0] + edge) & (t <= t[-1] - edge))[::stride]
    if rows.size < 4 * settings.rows_per_window:
        raise JobFailedError(f"{flight.source}: {t[-1] - t[0]:.1f} s of pose: too short for "
                             "the equation-error fit")

    def residual(theta: np.ndarray) -> np.ndarray:
        model = model_accelerations(inputs, n, theta, config)
        measured, model = consistent_accelerations(pose, inputs, model, sm, dt)
        return (measured - model)[rows]

    return residual, max(1, round(window / stride))


def _scales(prior: ParameterEstimate) -> np.ndarray:
    """Units of the fit's normalised θ: |prior value|, or the prior σ where that is 0."""
    scale = np.abs(prior.value).astype(float)
    zero = scale == 0.0
    scale[zero] = np.where(prior.sigma[zero] > 0.0, prior.sigma[zero], 1.0)
    return scale


def fit_equation_error(flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
                       settings: EquationErrorSettings | None = None) -> EquationErrorFit:
    """θ by equation error with the prior, and its HAC covariance (module docstring).

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds (any sampling; the longest segment, on a uniform grid).
    config : VehicleConfig
        Mass and rotor geometry.
    prior : ParameterEstimate
        The prior (start and regularisation), SI.
    settings : EquationErrorSettings, optional

    Returns
    -------
    EquationErrorFit

    Raises
    ------
    JobFailedError
        The flight is too short for the smoother.
    """
    settings = settings or EquationErrorSettings()
    residual, block = _residual_function(flight, config, settings)
    lags = max(1, round(settings.hac_windows * block))
    scale = _scales(prior)
    p_inv = np.linalg.pinv(prior.covariance / np.outer(scale, scale))
    u_prior = prior.value / scale
    theta = prior.value.astype(float).copy()
    kappa = float(block)
    for _ in range(settings.iterations):
        r0 = residual(theta)
        w = 1.0 / np.maximum(np.sqrt(np.mean(r0**2, axis=0)), 1e-12)
        X = theta_jacobian(residual, theta, r0) * (w[None, :, None] * scale[None, None, :])
        y = r0 * w
        H = np.einsum("nai,naj->ij", X, X)
        b = np.einsum("nai,na->i", X, y)
        A = H / kappa + p_inv
        step = np.linalg.solve(A, b / kappa + p_inv @ (u_prior - theta / scale)) * scale
        kappa = _kappa(X, y, step / scale, lags)
        new = _physical_step(theta, step)
        done = np.all(np.abs(new - theta) <= 1e-6 * scale)
        theta = new
        if done:
            break
    return _final(residual, theta, scale, p_inv, lags)


def _physical_step(theta: np.ndarray, step: np.ndarray) -> np.ndarray:
    """θ + step, halved until c_T, c_M and J stay positive."""
    for _ in range(20):
        new = theta + step
        if new[0] > 0.0 and new[2] > 0.0 and np.all(new[3:] > 0.0):
            return new
        step = 0.5 * step
    return theta


def _kappa(X: np.ndarray, y: np.ndarray, du: np.ndarray, lags: int) -> float:
    """Effective-sample factor of the scores at the linearised solution, ≥ 1."""
    scores = np.einsum("nai,na->ni", X, y - X @ du)
    white = np.trace(S_hac_simple(scores, nlags=0))
    return max(1.0, float(np.trace(S_hac_simple(scores, nlags=lags)) / max(white, 1e-300)))


def _final(residual: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
           scale: np.ndarray, p_inv: np.ndarray, lags: int) -> EquationErrorFit:
    """The sandwich covariance at the converged θ."""
    r0 = residual(theta)
    rms = np.sqrt(np.mean(r0**2, axis=0))
    w = 1.0 / np.maximum(rms, 1e-12)
    X = theta_jacobian(residual, theta, r0) * (w[None, :, None] * scale[None, None, :])
    y = r0 * w
    scores = np.einsum("nai,na->ni", X, y)
    S = S_hac_simple(scores, nlags=lags)
    kappa = max(1.0, float(np.trace(S) / max(np.trace(S_hac_simple(scores, 0)), 1e-300)))
    A_inv = np.linalg.inv(np.einsum("nai,naj->ij", X, X) / kappa + p_inv)
    cov = A_inv @ (S / kappa**2 + p_inv) @ A_inv
    cov = 0.5 * (cov + cov.T) * np.outer(scale, scale)
    return EquationErrorFit(ParameterEstimate(theta, cov), rms, len(r0), len(r0) / kappa)
