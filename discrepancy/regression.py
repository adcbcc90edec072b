"""Weighted least squares of the residual with effective-sample statistics.

The smoothed residual is correlated over one smoother window (D samples), so the
likelihood counts n/D effective samples and the least-squares covariance is inflated by
D: the naive white-noise statistics would be overconfident and flag effects on clean
flights. Each axis has its own noise variance, concentrated out of the likelihood.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from mavsysid.discrepancy.candidates import theta_columns
from mavsysid.discrepancy.residuals import ResidualProblem
from mavsysid.vehicle.model_effects import ModelEffect
from scipy.stats import chi2

__all__ = ["Regression", "fit_theta", "lr_p", "profile_interval", "refine_minimum"]

_CHI2_95 = float(chi2.ppf(0.95, 1))


class Regression:
    """Weighted least squares on the training rows, with effective-sample statistics."""

    def __init__(self, rows: np.ndarray, weights: np.ndarray, block: int) -> None:
        self.rows = rows
        self.weights = weights
        self.block = block

    def stack(self, r: np.ndarray, cols: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        y = (r[self.rows] * self.weights).ravel()
        X = np.concatenate([c[self.rows] for c in cols], axis=-1) if cols else np.zeros(
            (len(self.rows), 6, 0))
        X = (X * self.weights[None, :, None]).reshape(y.size, -1)
        return y, X

    def fit(self, y: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-axis RSS (6,), coefficients and covariance (inflated by the block) of y ≈ X β."""
        if X.shape[1] == 0:
            return np.sum(y.reshape(-1, 6) ** 2, axis=0), np.zeros(0), np.zeros((0, 0))
        norm = np.linalg.norm(X, axis=0)
        norm[norm == 0.0] = 1.0
        Xn = X / norm
        # The minimum-norm least-squares solution through the (small) normal matrix:
        # pinv(XᵀX) Xᵀ = pinv(X). The columns are normalised, so XᵀX squares a modest
        # condition number; an SVD of the tall X costs ~100× more per fit.
        gram_inv = np.linalg.pinv(Xn.T @ Xn)
        beta_n = gram_inv @ (Xn.T @ y)
        e = y - Xn @ beta_n
        rss = np.sum(e.reshape(-1, 6) ** 2, axis=0)
        s2 = float(rss.sum()) / max(y.size - X.shape[1], 1)
        cov_n = gram_inv * s2 * self.block
        return rss, beta_n / norm, cov_n / np.outer(norm, norm)

    def bic(self, rss: np.ndarray, k: int) -> float:
        """Effective BIC with one noise variance per axis, concentrated out.

        −2 log L = Σ_a n_eff log(RSS_a / n) (+ const), n the rows per axis and
        n_eff = n / D; penalty k log(6 n_eff). The per-axis variances make the criterion
        independent of the weights, which only steer the coefficient estimates.
        """
        return self.deviance(rss) + self.penalty(k)

    def penalty(self, k: int) -> float:
        """BIC penalty of k parameters: k log(6 n_eff)."""
        return float(k * np.log(6 * len(self.rows) / self.block))

    def deviance(self, rss: np.ndarray) -> float:
        """−2 log L (up to a constant) over the effective samples, per-axis variances."""
        n = len(self.rows)
        return float(n / self.block * np.sum(np.log(np.asarray(rss) / n)))


def fit_theta(problem: ResidualProblem, rows: np.ndarray, fixed: Sequence[ModelEffect] = (),
              iterations: int = 4) -> tuple[ResidualProblem, np.ndarray]:
    """Gauss–Newton equation-error fit of θ on the training rows (effects ``fixed``).

    Returns the problem at the fitted θ and the axis weights 1/σ (σ the RMS of each
    axis's final residual).
    """
    weights = np.ones(6)
    for _ in range(iterations):
        r0 = problem.residual(fixed)
        weights = 1.0 / np.maximum(np.sqrt(np.mean(r0[rows] ** 2, axis=0)), 1e-9)
        reg = Regression(rows, weights, 1)
        _, beta, _ = reg.fit(*reg.stack(r0, [theta_columns(problem, fixed, r0)]))
        theta = problem.theta + beta
        if np.any(theta[3:] <= 0.0) or theta[0] <= 0.0:
            break  # a step to an unphysical θ: keep the last physical one
        problem = replace(problem, theta=theta)
        if np.all(np.abs(beta) <= 1e-6 * np.abs(theta) + 1e-12):
            break
    r0 = problem.residual(fixed)
    weights = 1.0 / np.maximum(np.sqrt(np.mean(r0[rows] ** 2, axis=0)), 1e-9)
    return problem, weights


def refine_minimum(grid: np.ndarray, dev: np.ndarray) -> float:
    """Vertex of the parabola through the grid minimum and its neighbours."""
    i = int(np.argmin(dev))
    if i == 0 or i == grid.size - 1:
        return float(grid[i])
    x, y = grid[i - 1:i + 2], dev[i - 1:i + 2]
    a, b, _ = np.polyfit(x, y, 2)
    return float(np.clip(-b / (2 * a), x[0], x[2])) if a > 0 else float(grid[i])


def profile_interval(grid: np.ndarray, dev: np.ndarray) -> tuple[float, float]:
    """95 % profile-likelihood interval: deviance(v) − min ≤ χ²₁(0.95)."""
    stat = dev - dev.min()
    inside = np.flatnonzero(stat <= _CHI2_95)
    lo_i, hi_i = inside.min(), inside.max()

    def cross(i: int, j: int) -> float:
        if j < 0 or j >= grid.size:
            return float(grid[i])
        # Linear interpolation of the crossing between a point inside and one outside.
        f = (_CHI2_95 - stat[i]) / (stat[j] - stat[i])
        return float(grid[i] + f * (grid[j] - grid[i]))

    return cross(lo_i, lo_i - 1), cross(hi_i, hi_i + 1)


def lr_p(deviance_drop: float, dof: int) -> float:
    """p-value of the likelihood-ratio statistic (the deviance drop) against χ²(dof)."""
    return float(chi2.sf(max(deviance_drop, 0.0), dof))
