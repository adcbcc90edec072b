"""Weighted least squares over stacked axes with a Newey–West covariance, and its reverse.

The balance rows y_{t,a} = Σ_j X_{t,a,j} β_j + e_{t,a} (t time, a axis) are fitted with
one weight per axis, w_a = 1 / RMS of that axis' residual (two passes), so that axes in
different units and noise count alike. The residuals of a smoothed balance are correlated
over the smoother's and the unmodelled dynamics' time scales; the covariance is therefore
the sandwich A⁻¹ S A⁻¹ with A = Σ_t Σ_a w_a² X Xᵀ and S the Newey–West (Bartlett)
long-run covariance of the per-time scores s_t = Σ_a w_a² X_{t,a} e_{t,a}
(`mavsysid.estimation.robust.hac_covariance`, the one HAC of the estimator), summed over
independent segments.

Errors in the regressors. The rotor side carries errors too (speed-sensing noise and lag,
torques the controller cancels), which bias the slope towards zero. The reverse regression
of a regressor on the measured side is biased the other way; with errors on both sides
the coefficient lies between the two (Frisch's bounds). The reverse value of each main
coefficient is returned so that its interval can cover both (`reverse_coefficient`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.robust import hac_covariance

__all__ = ["LinearFit", "fit_rows", "reverse_coefficient"]


#: Passes of the per-axis weighting.
WEIGHT_PASSES = 2


@dataclass(frozen=True)
class LinearFit:
    """A weighted least-squares fit of stacked axes.

    Attributes
    ----------
    coefficients : ndarray, shape (P,)
    covariance : ndarray, shape (P, P)
        Sandwich with the Newey–West S; inf on the diagonal of columns the rows do not
        excite (all zero).
    weights : ndarray, shape (A,)
        Per-axis weights w_a (1 / residual RMS).
    residual_rms : ndarray, shape (A,)
        RMS of the final residual per axis.
    rows : int
        Time rows used.
    """

    coefficients: np.ndarray
    covariance: np.ndarray
    weights: np.ndarray
    residual_rms: np.ndarray
    rows: int

    @property
    def sigma(self) -> np.ndarray:
        """σ of each coefficient, shape (P,)."""
        return np.sqrt(np.diag(self.covariance))


def _solve(y: np.ndarray, X: np.ndarray, w: np.ndarray, live: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """β (P,) on the live columns and the bread A (live × live)."""
    Xw = X[:, :, live] * w[None, :, None]
    A = np.einsum("tai,taj->ij", Xw, Xw)
    b = np.einsum("tai,ta->i", Xw, y * w[None, :])
    beta = np.zeros(X.shape[2])
    beta[live] = np.linalg.solve(A, b)
    return beta, A


def fit_rows(y: Sequence[np.ndarray], X: Sequence[np.ndarray], covariance: bool = True
             ) -> LinearFit:
    """Fit β to rows of one or more independent segments (module docstring).

    Parameters
    ----------
    y : sequence of ndarray, each shape (T_s, A)
        Measured side per segment.
    X : sequence of ndarray, each shape (T_s, A, P)
        Regressors per segment.
    covariance : bool
        False: skip the Newey–West covariance (the result's is NaN).

    Returns
    -------
    LinearFit

    Raises
    ------
    numpy.linalg.LinAlgError
        The live columns are linearly dependent.
    """
    Y, XX = np.concatenate(y), np.concatenate(X)
    live = np.sqrt(np.einsum("tai,tai->i", XX, XX)) > 0.0
    rms = np.sqrt(np.mean(Y**2, axis=0))
    w = 1.0 / np.where(rms > 0, rms, 1.0)
    for _ in range(WEIGHT_PASSES):
        beta, A = _solve(Y, XX, w, live)
        rms = np.sqrt(np.mean((Y - XX @ beta) ** 2, axis=0))
        w = 1.0 / np.where(rms > 0, rms, 1.0)
    beta, A = _solve(Y, XX, w, live)
    rms = np.sqrt(np.mean((Y - XX @ beta) ** 2, axis=0))
    if not covariance:
        return LinearFit(beta, np.full((XX.shape[2],) * 2, np.nan), w, rms, len(Y))
    S = np.zeros_like(A)
    for ys, xs in zip(y, X, strict=True):
        e = ys - xs @ beta
        scores = np.einsum("tai,ta->ti", xs[:, :, live] * (w**2)[None, :, None], e)
        if len(scores) > 2:
            S += hac_covariance(scores)
    A_inv = np.linalg.inv(A)
    cov = np.full((XX.shape[2],) * 2, 0.0)
    cov[np.ix_(live, live)] = A_inv @ S @ A_inv
    cov[~live, ~live] = np.inf
    return LinearFit(beta, 0.5 * (cov + cov.T), w, rms, len(Y))


def reverse_coefficient(y: Sequence[np.ndarray], X: Sequence[np.ndarray], column: int,
                        axes: Sequence[int], weights: np.ndarray) -> float:
    """Column ``column``'s coefficient from the reverse regression (module docstring).

    The column is regressed on the measured side and the other live columns, over the
    rows of ``axes`` weighted as in the forward fit; the coefficient is 1 / (the slope on
    the measured side).

    Parameters
    ----------
    y, X : sequences of ndarray
        As for `fit_rows`.
    column : int
    axes : sequence of int
        The axes whose rows carry the column.
    weights : ndarray, shape (A,)
        The forward fit's per-axis weights.

    Returns
    -------
    float
        NaN when the slope is 0.
    """
    axes = list(axes)
    Y = np.concatenate(y)[:, axes] * weights[axes]
    XX = np.concatenate(X)[:, axes, :] * weights[axes][None, :, None]
    live = np.sqrt(np.einsum("tai,tai->i", XX, XX)) > 0.0
    live[column] = False
    others = XX[:, :, live].reshape(Y.size, int(live.sum()))
    design = np.concatenate([Y.reshape(-1, 1), others], axis=1)
    target = XX[:, :, column].reshape(-1)
    slope = np.linalg.lstsq(design.T @ design, design.T @ target, rcond=None)[0][0]
    return float(1.0 / slope) if slope != 0.0 else float("nan")
