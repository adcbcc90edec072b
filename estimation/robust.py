"""The one robust covariance of the estimator: Newey–West (HAC) for residuals that are not white.

The naive covariance of a weighted least-squares (or MAP) estimate assumes every whitened
residual is independent with unit variance. When the model misses some physics the
residuals carry the missing force: correlated over seconds and larger than assumed, and
that σ is several times too small. `hac_covariance` is the Newey–West (Bartlett)
long-run covariance of a score series, its bandwidth by Andrews's (1991) AR(1) plug-in
(`andrews_bartlett_bandwidth`): the estimator of statsmodels' ``S_hac_simple`` (which the
tests compare against) with the lagged products from one FFT, since the batch
refinement's bandwidths reach hundreds of samples. The balance's regressions
(`mavsysid.estimation.balance.regression`) and the batch refinement use it.

For the batch: the estimate moves with the residuals as Δθ = −(H⁻¹ Jᵀ r)_θ, and each time
sample's share of it, its *influence*, is a series whose long-run variance is the variance
of θ̂ whatever the residuals' correlation (`robust_theta_covariance`). Fitted residuals
are smaller than the errors they estimate (r = (I − P) ε), so the plain HAC is biased low;
`inflated_theta_covariance` calibrates it against the same HAC of white unit residuals
projected the same way, and inflates the naive covariance by the ratio (never below 1).
`disagreement_widening`: σ' = √(σ² + Δ²) where two estimators consistent under a correct
model disagree beyond `DISAGREEMENT_SIGMAS` combined σ.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp

__all__ = ["DISAGREEMENT_SIGMAS", "andrews_bartlett_bandwidth", "disagreement_widening",
           "hac_covariance", "inflated_theta_covariance", "inflation_from_scores",
           "influence_by_sample", "robust_theta_covariance", "widened"]


#: Two estimators that are both consistent under a correct model differ by more than this
#: many combined σ in 5 % of flights (per parameter); beyond it, their disagreement is
#: counted as model error.
DISAGREEMENT_SIGMAS = 2.0

#: AR(1) coefficients are clipped here: a unit root would make the bandwidth infinite.
MAX_AUTOCORRELATION = 0.995


def influence_by_sample(
    jacobian: sp.spmatrix | np.ndarray, residuals: np.ndarray, theta_solution: np.ndarray,
    sample: np.ndarray, n_samples: int,
) -> np.ndarray:
    """Each time sample's influence on θ̂: Σ over its rows j of (H⁻¹ Jᵀ)_θj r_j.

    Parameters
    ----------
    jacobian : sparse or ndarray, shape (M, U)
        Jacobian of the whitened residuals over all U unknowns, at the optimum.
    residuals : ndarray, shape (M,)
        Whitened residuals at the optimum (unit variance if the model were right).
    theta_solution : ndarray, shape (U, P)
        H⁻¹ E: the columns of (JᵀJ)⁻¹ that belong to the P parameters θ (E selects them).
    sample : ndarray of int, shape (M,)
        The time sample each row belongs to, 0 … n_samples − 1; a negative entry leaves
        the row out (e.g. prior rows, which are independent of the flight).
    n_samples : int

    Returns
    -------
    ndarray, shape (n_samples, P)
        In θ's units (those of ``theta_solution``); the rows sum to −Δθ of a full step.
    """
    rows = np.asarray(jacobian @ theta_solution) * np.asarray(residuals)[:, None]
    keep = np.asarray(sample) >= 0
    out = np.zeros((n_samples, rows.shape[1]))
    np.add.at(out, np.asarray(sample)[keep], rows[keep])
    return out


def andrews_bartlett_bandwidth(scores: np.ndarray) -> float:
    """Bartlett-kernel bandwidth by Andrews's (1991) AR(1) plug-in rule, in samples.

    Each column, standardised, is fitted as an AR(1) with coefficient ρ_a (clipped to
    `MAX_AUTOCORRELATION`) and innovation variance s_a² = 1 − ρ_a²; then
    α = Σ 4 ρ² s⁴ / ((1−ρ)⁶ (1+ρ)²) / Σ s⁴ / (1−ρ)⁴ and L = 1.1447 (α T)^(1/3).

    Parameters
    ----------
    scores : ndarray, shape (T, P)
        A time series per column, consecutive equally spaced samples.

    Returns
    -------
    float
        The bandwidth L ≥ 0, at most T − 1.
    """
    x = np.asarray(scores, float)
    x = x - x.mean(axis=0)
    scale = x.std(axis=0)
    x = x[:, scale > 0] / scale[scale > 0]
    n = x.shape[0]
    if x.shape[1] == 0 or n < 3:
        return 0.0
    rho = np.sum(x[1:] * x[:-1], axis=0) / np.sum(x[:-1] ** 2, axis=0)
    rho = np.clip(rho, -MAX_AUTOCORRELATION, MAX_AUTOCORRELATION)
    s4 = (1.0 - rho**2) ** 2
    alpha = (np.sum(4 * rho**2 * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2))
             / np.sum(s4 / (1 - rho) ** 4))
    return float(min(1.1447 * (alpha * n) ** (1.0 / 3.0), n - 1))


def hac_covariance(scores: np.ndarray, bandwidth: float | None = None) -> np.ndarray:
    """Newey–West (Bartlett) long-run covariance of the sum of ``scores`` over time.

    The estimator of statsmodels' ``S_hac_simple`` with ``weights_bartlett`` (which the
    tests compare against), with the lagged products from one FFT instead of a loop over
    lags: the batch refinement's bandwidths reach hundreds of samples.

    Parameters
    ----------
    scores : ndarray, shape (T, P)
        Consecutive equally spaced samples (not divided by T: the result is the
        covariance of their sum).
    bandwidth : float, optional
        L, samples; `andrews_bartlett_bandwidth` of ``scores`` by default.

    Returns
    -------
    ndarray, shape (P, P)
        Σ_{|l| ≤ L} (1 − |l|/(L+1)) Σ_t u_t u_{t−l}ᵀ, symmetric.
    """
    x = np.asarray(scores, float)
    if bandwidth is None:
        bandwidth = andrews_bartlett_bandwidth(x)
    T = x.shape[0]
    lags = int(np.floor(min(bandwidth, T - 1)))
    n_fft = 1 << int(np.ceil(np.log2(2 * T)))
    X = np.fft.rfft(x, n_fft, axis=0)
    # gamma[l, a, b] = Σ_t x[t + l, a] x[t, b] for l = 0 … lags.
    gamma = np.fft.irfft(X[:, :, None] * np.conj(X[:, None, :]), n_fft, axis=0)[:lags + 1]
    weights = 1.0 - np.arange(lags + 1) / (lags + 1.0)
    S = np.einsum("l,lab->ab", weights[1:], gamma[1:])
    S = gamma[0] + S + S.T
    return 0.5 * (S + S.T)


def robust_theta_covariance(
    jacobian: sp.spmatrix | np.ndarray, residuals: np.ndarray, theta_solution: np.ndarray,
    sample: np.ndarray, n_samples: int, bandwidth: float | None = None,
) -> np.ndarray:
    """θ covariance robust to correlated, mis-scaled residuals (sandwich / HAC).

    Rows with a sample index ≥ 0 enter through the HAC long-run covariance of their
    influence (`influence_by_sample`, `hac_covariance`); rows marked −1 (a prior,
    independent of the flight) keep their assumed unit variance, G_pᵀ G_p with
    G = J H⁻¹ E. With white unit-variance residuals the result tends to the naive
    θ block of H⁻¹.

    Parameters
    ----------
    jacobian, residuals, theta_solution, sample, n_samples
        As in `influence_by_sample`.
    bandwidth : float, optional
        Bartlett bandwidth in samples; Andrews's plug-in by default.

    Returns
    -------
    ndarray, shape (P, P)
        In the units of ``theta_solution`` (scale it as θ is scaled).
    """
    scores = influence_by_sample(jacobian, residuals, theta_solution, sample, n_samples)
    prior_rows = np.flatnonzero(np.asarray(sample) < 0)
    G_prior = np.asarray(jacobian[prior_rows] @ theta_solution)
    return hac_covariance(scores, bandwidth) + G_prior.T @ G_prior


def inflated_theta_covariance(
    jacobian: sp.spmatrix | np.ndarray, residuals: np.ndarray,
    solve: Callable[[np.ndarray], np.ndarray], theta_columns: np.ndarray, sample: np.ndarray,
    n_samples: int, draws: int = 8, seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """The naive θ covariance, inflated by the residuals' HAC against a correct model's.

    For each parameter a, the variance ratio ρ_a = HAC_aa(r) / E[HAC_aa((I − P) ε)], ε white
    and unit (``draws`` seeded Monte-Carlo draws, P = J H⁻¹ Jᵀ), both at the data's
    Andrews bandwidth; the result is D C D with C the θ block of H⁻¹ and
    D = diag(√max(1, ρ_a)): residuals that are correlated or larger than assumed widen the
    interval, and a correct model leaves it (nearly) as it is.

    Parameters
    ----------
    jacobian : sparse or ndarray, shape (M, U)
        Whitened residuals' Jacobian at the optimum.
    residuals : ndarray, shape (M,)
        Whitened residuals at the optimum.
    solve : callable
        ``solve(b)`` returns H⁻¹ b for b of shape (U, k), H = JᵀJ (plus any prior rows
        already in J).
    theta_columns : ndarray of int, shape (P,)
        The columns of the θ unknowns.
    sample, n_samples
        As in `influence_by_sample` (prior rows −1).
    draws : int
        Monte-Carlo draws of the white reference.
    seed : int

    Returns
    -------
    covariance : ndarray, shape (P, P)
        In the units of θ's columns.
    inflation : ndarray, shape (P,)
        σ multiplier of each parameter, ≥ 1.
    """
    U = jacobian.shape[1]
    E = np.zeros((U, len(theta_columns)))
    E[theta_columns, np.arange(len(theta_columns))] = 1.0
    B = solve(E)
    naive = B[theta_columns]
    scores = influence_by_sample(jacobian, residuals, B, sample, n_samples)
    prior_rows = np.flatnonzero(np.asarray(sample) < 0)
    G_prior = np.asarray(jacobian[prior_rows] @ B)
    eps = np.random.default_rng(seed).standard_normal((jacobian.shape[0], draws))
    white = eps - np.asarray(jacobian @ solve(np.asarray(jacobian.T @ eps)))
    white_scores = [influence_by_sample(jacobian, white[:, i], B, sample, n_samples)
                    for i in range(draws)]
    return inflation_from_scores(0.5 * (naive + naive.T), scores, white_scores,
                                 G_prior.T @ G_prior)


def inflation_from_scores(
    naive: np.ndarray, scores: np.ndarray, white_scores: Sequence[np.ndarray] | np.ndarray,
    prior: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """`inflated_theta_covariance` from the influence series, however they were formed.

    Parameters
    ----------
    naive : ndarray, shape (P, P)
        The θ block of H⁻¹.
    scores : ndarray, shape (T, P)
        Each time sample's influence on θ̂ with the fitted residuals (`influence_by_sample`).
    white_scores : sequence of ndarray, each shape (T, P)
        The same with each Monte-Carlo draw of projected white residuals (I − P) ε.
    prior : ndarray, shape (P, P)
        G_pᵀ G_p of the prior rows (independent of the flight).

    Returns
    -------
    covariance : ndarray, shape (P, P)
    inflation : ndarray, shape (P,)
        As `inflated_theta_covariance`.
    """
    bandwidth = andrews_bartlett_bandwidth(scores)
    data = np.diag(hac_covariance(scores, bandwidth) + prior)
    reference = np.mean([np.diag(hac_covariance(w, bandwidth) + prior) for w in white_scores],
                        axis=0)
    inflation = np.sqrt(np.maximum(1.0, data / reference))
    return naive * np.outer(inflation, inflation), inflation


def disagreement_widening(value: np.ndarray, sigma: np.ndarray, other_value: np.ndarray,
                          other_sigma: np.ndarray) -> np.ndarray:
    """σ multipliers (6,) ≥ 1 that make each interval hold a second estimator's disagreement.

    The batch MAP (output error) and the equation-error fit are both consistent when the
    model is right, so they differ by about their combined σ. When the physics differ from
    the model each converges to its own pseudo-true θ, and the gap between them is a
    measured lower bound of what the mismatch does to θ (the idea of Hausman's
    specification test). A parameter whose two estimates differ by more than
    `DISAGREEMENT_SIGMAS` combined σ gets σ' = √(σ² + Δ²); the others keep σ.

    Parameters
    ----------
    value, sigma : ndarray, shape (P,)
        The reported estimate and its σ.
    other_value, other_sigma : ndarray, shape (P,)
        The independent estimate and its σ, same units.

    Returns
    -------
    ndarray, shape (P,)
        σ'/σ, ≥ 1.
    """
    delta = np.asarray(value, float) - np.asarray(other_value, float)
    sigma = np.asarray(sigma, float)
    spread = np.sqrt(sigma**2 + np.asarray(other_sigma, float) ** 2)
    far = np.abs(delta) > DISAGREEMENT_SIGMAS * spread
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.sqrt(1.0 + (delta / sigma) ** 2)
    return np.where(far & np.isfinite(factor), factor, 1.0)


def widened(covariance: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """D C D with D = diag(``factor``): σ scaled, correlations kept; shape (P, P)."""
    return np.asarray(covariance) * np.outer(factor, factor)
