"""The sandwich/HAC θ covariance: right coverage where the naive one is too small."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from mavsysid.estimation.robust import (
    andrews_bartlett_bandwidth,
    disagreement_widening,
    hac_covariance,
    inflated_theta_covariance,
    influence_by_sample,
    robust_theta_covariance,
    widened,
)
from statsmodels.stats.sandwich_covariance import S_hac_simple


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    """A stationary AR(1) series of unit variance, shape (n,)."""
    e = rng.standard_normal(n) * np.sqrt(1.0 - rho**2)
    x = np.empty(n)
    x[0] = rng.standard_normal()
    for i in range(1, n):
        x[i] = rho * x[i - 1] + e[i]
    return x


def _coverage(rho: float, n: int = 1500, reps: int = 150) -> tuple[float, float]:
    """Share of 95 % intervals of a slope covering the truth: naive and HAC.

    y = 1 − 0.5 x + e with x and e both AR(1) of coefficient ρ, unit variance; the
    residuals are 'whitened' at the assumed σ = 1, as the batch refinement's are.
    """
    rng = np.random.default_rng(18)
    naive = robust = 0
    for _ in range(reps):
        X = np.column_stack([np.ones(n), _ar1(rng, n, rho)])
        y = X @ np.array([1.0, -0.5]) + _ar1(rng, n, rho)
        B = np.linalg.inv(X.T @ X)
        b = B @ X.T @ y
        cov = robust_theta_covariance(X, y - X @ b, B, np.arange(n), n)
        naive += abs(b[1] + 0.5) <= 1.96 * np.sqrt(B[1, 1])
        robust += abs(b[1] + 0.5) <= 1.96 * np.sqrt(cov[1, 1])
    return naive / reps, robust / reps


def test_hac_covers_where_the_naive_interval_is_too_small() -> None:
    naive, robust = _coverage(rho=0.7)
    assert naive < 0.85
    assert robust >= 0.9


def test_hac_agrees_with_naive_on_white_residuals() -> None:
    naive, robust = _coverage(rho=0.0)
    assert 0.9 <= naive <= 0.99
    assert 0.9 <= robust <= 0.99


def test_bandwidth_grows_with_autocorrelation() -> None:
    rng = np.random.default_rng(3)
    white = andrews_bartlett_bandwidth(rng.standard_normal((2000, 2)))
    slow = andrews_bartlett_bandwidth(np.column_stack([_ar1(rng, 2000, 0.95)] * 2))
    assert white < 5.0
    assert slow > 5 * white
    assert andrews_bartlett_bandwidth(np.zeros((10, 2))) == 0.0


def test_hac_with_zero_bandwidth_is_the_sum_of_outer_products() -> None:
    u = np.random.default_rng(4).standard_normal((50, 3))
    np.testing.assert_allclose(hac_covariance(u, 0.0), u.T @ u, rtol=1e-12)


def test_influence_sums_to_the_parameter_step() -> None:
    rng = np.random.default_rng(5)
    J = rng.standard_normal((40, 3))
    r = rng.standard_normal(40)
    B = np.linalg.inv(J.T @ J)
    sample = np.repeat(np.arange(20), 2)
    u = influence_by_sample(sp.csr_matrix(J), r, B, sample, 20)
    assert u.shape == (20, 3)
    np.testing.assert_allclose(u.sum(axis=0), B @ J.T @ r, rtol=1e-10)
    left_out = influence_by_sample(J, r, B, np.where(sample < 5, -1, sample), 20)
    np.testing.assert_allclose(left_out[:5], 0.0)
    np.testing.assert_allclose(left_out[5:], u[5:], rtol=1e-12)


def test_nuisance_unknowns_are_profiled_out_and_prior_rows_kept_at_unit_variance() -> None:
    """Per-block offsets as nuisance unknowns (like the batch's states) plus a θ prior row.

    The θ columns of the full H⁻¹ give the same robust covariance as the problem with the
    offsets partialled out (Frisch–Waugh), and the prior row adds G_pᵀ G_p.
    """
    rng = np.random.default_rng(6)
    blocks, per = 30, 20
    n = blocks * per
    x = rng.standard_normal(n)
    D = np.kron(np.eye(blocks), np.ones((per, 1)))
    J = np.vstack([np.column_stack([D, x]), np.append(np.zeros(blocks), 0.3)])
    r = np.append(0.5 * rng.standard_normal(n), 0.2)
    H = J.T @ J
    E = np.zeros((blocks + 1, 1))
    E[-1] = 1.0
    B = np.linalg.solve(H, E)
    sample = np.append(np.arange(n), -1)
    full = robust_theta_covariance(sp.csr_matrix(J), r, B, sample, n, bandwidth=0.0)
    x_within = x - D @ (D.T @ x) / per
    G = x_within * B[-1, 0]
    expected = np.sum((G * r[:n]) ** 2) + (0.3 * B[-1, 0]) ** 2
    np.testing.assert_allclose(full[0, 0], expected, rtol=1e-9)


def _inflated_coverage(rho: float, n: int = 800, reps: int = 60) -> tuple[float, float]:
    """As `_coverage`, with `inflated_theta_covariance` (white reference by Monte Carlo)."""
    rng = np.random.default_rng(19)
    naive = robust = 0
    for _ in range(reps):
        X = np.column_stack([np.ones(n), _ar1(rng, n, rho)])
        y = X @ np.array([1.0, -0.5]) + _ar1(rng, n, rho)
        H_inv = np.linalg.inv(X.T @ X)
        b = H_inv @ X.T @ y
        cov, inflation = inflated_theta_covariance(
            X, y - X @ b, lambda rhs, H_inv=H_inv: H_inv @ rhs, np.arange(2), np.arange(n), n)
        assert np.all(inflation >= 1.0)
        naive += abs(b[1] + 0.5) <= 1.96 * np.sqrt(H_inv[1, 1])
        robust += abs(b[1] + 0.5) <= 1.96 * np.sqrt(cov[1, 1])
    return naive / reps, robust / reps


def test_inflated_covariance_covers_with_correlated_errors() -> None:
    naive, robust = _inflated_coverage(rho=0.7)
    assert naive < 0.85
    assert robust >= 0.9


def test_inflated_covariance_stays_near_naive_on_white_errors() -> None:
    rng = np.random.default_rng(20)
    n = 1000
    X = np.column_stack([np.ones(n), rng.standard_normal(n)])
    H_inv = np.linalg.inv(X.T @ X)
    r = rng.standard_normal(n)
    r -= X @ (H_inv @ X.T @ r)
    cov, inflation = inflated_theta_covariance(X, r, lambda rhs: H_inv @ rhs, np.arange(2),
                                               np.arange(n), n, draws=16)
    assert np.all(inflation < 1.3)
    np.testing.assert_allclose(np.diag(cov), np.diag(H_inv) * inflation**2, rtol=1e-12)


def test_hac_matches_statsmodels() -> None:
    u = np.random.default_rng(7).standard_normal((300, 3)).cumsum(axis=0) * 0.1
    for lags in (0, 1, 17, 299):
        np.testing.assert_allclose(hac_covariance(u, lags), S_hac_simple(u, nlags=lags),
                                   rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_disagreement_widening_holds_the_other_estimate(seed):
    """A disagreement beyond 2 combined σ widens σ to cover it; agreement leaves σ alone."""
    rng = np.random.default_rng(seed)
    sigma, other_sigma = rng.uniform(0.5, 2.0, 6), rng.uniform(0.5, 2.0, 6)
    spread = np.sqrt(sigma**2 + other_sigma**2)
    delta = spread * np.array([0.5, 1.9, 2.1, 5.0, -3.0, -1.0])
    factor = disagreement_widening(delta, sigma, np.zeros(6), other_sigma)
    far = np.abs(delta) > 2.0 * spread
    np.testing.assert_array_equal(factor[~far], 1.0)
    assert np.all(factor[far] * sigma[far] >= np.abs(delta[far]))
    cov = np.diag(sigma**2) + 0.1 * np.outer(sigma, sigma)
    wide = widened(cov, factor)
    corr = cov / np.outer(np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov)))
    wide_corr = wide / np.outer(np.sqrt(np.diag(wide)), np.sqrt(np.diag(wide)))
    np.testing.assert_allclose(wide_corr, corr)
