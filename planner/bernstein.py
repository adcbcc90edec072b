"""Ranges of polynomials on [0, 1] from their Bernstein coefficients.

A polynomial lies in the hull of its Bernstein coefficients on [0, 1], the end ones are its
end values, and halving (de Casteljau) shrinks the hull quadratically onto the true range:
`range_violation` decides exactly (to rounding) whether a polynomial leaves an interval,
the answer the derivative's roots give, cheaper and without companion-matrix trouble at
clustered extrema. Used by `mavsysid.planner.feasibility` for the polynomial constraints.
"""

from __future__ import annotations

from math import comb

import numba
import numpy as np

__all__ = ["bernstein_matrix", "linear_violation", "range_violation", "square_norm",
           "square_weights", "to_bernstein"]

_MAX_DEPTH = 40  # hull excess shrinks as 4^-depth: at 40 it is far below rounding
_ROUNDING = 1e-14  # rounding allowance per unit of Σ|terms| (45 ε; ≤ 1 ε seen in tests)


def bernstein_matrix(n: int) -> np.ndarray:
    """B with Bernstein coefficients β = B a of Σ a_j s^j on [0, 1], degree n."""
    return np.array([[comb(i, j) / comb(n, j) for j in range(n + 1)] for i in range(n + 1)])


def square_weights(m: int) -> np.ndarray:
    """W with Bernstein coefficients of p² = Σ_(i+j=k) W_ij β_i β_j, degree m."""
    return np.array([[comb(m, i) * comb(m, j) / comb(2 * m, i + j) for j in range(m + 1)]
                     for i in range(m + 1)])


@numba.njit(cache=True)
def to_bernstein(bern: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Bernstein coefficients of Σ c_j s^j; ``bern`` is `bernstein_matrix` of its degree."""
    beta = np.zeros(c.size)
    for i in range(c.size):
        for j in range(i + 1):
            beta[i] += bern[i, j] * c[j]
    return beta


@numba.njit(cache=True)
def range_violation(beta: np.ndarray, lo: float, hi: float) -> float:
    """Where the polynomial with Bernstein coefficients β leaves [lo, hi] on [0, 1].

    Returns s ≥ 0 where its value is outside (or the undecided spot at the maximum
    depth), or −1 when the whole range is inside. Depth-first, left half first.
    """
    n = beta.size
    stack = np.empty((_MAX_DEPTH + 2, n))
    starts = np.empty(_MAX_DEPTH + 2)
    depths = np.empty(_MAX_DEPTH + 2, dtype=np.int64)
    stack[0] = beta
    starts[0], depths[0], top = 0.0, 0, 1
    while top > 0:
        top -= 1
        b, a, depth = stack[top].copy(), starts[top], depths[top]
        width = 0.5**depth
        if not lo <= b[0] <= hi:
            return a
        if not lo <= b[n - 1] <= hi:
            return a + width
        if lo <= b.min() and b.max() <= hi:
            continue
        if depth >= _MAX_DEPTH:
            return a
        # de Casteljau at ½: the halves' coefficients are the first and last entries of
        # the successive averaging rows.
        left, right = np.empty(n), np.empty(n)
        left[0], right[n - 1] = b[0], b[n - 1]
        for r in range(1, n):
            for i in range(n - r):
                b[i] = 0.5 * (b[i] + b[i + 1])
            left[r], right[n - 1 - r] = b[0], b[n - 1 - r]
        stack[top], starts[top], depths[top] = right, a + 0.5 * width, depth + 1
        stack[top + 1], starts[top + 1], depths[top + 1] = left, a, depth + 1
        top += 2
    return -1.0


@numba.njit(cache=True)
def linear_violation(bern: np.ndarray, c: np.ndarray, lo: float, hi: float) -> float:
    """`range_violation` of Σ c_j s^j, the limits tightened by _ROUNDING × Σ|c_j|."""
    tol = _ROUNDING * np.sum(np.abs(c))
    return range_violation(to_bernstein(bern, c), lo + tol, hi - tol)


@numba.njit(cache=True)
def square_norm(dc: np.ndarray, column: int, bern: np.ndarray, weights: np.ndarray,
                lift: float) -> tuple[np.ndarray, float]:
    """Bernstein coefficients of Σ_axis q_axis(s)², q = dc[:, column + axis] (+ lift on z).

    Squared in the Bernstein basis, whose coefficients are of the size of the values:
    squaring the monomial coefficients instead loses up to 1e-8 relative to cancellation.
    Also returns the rounding allowance: Σ_axis max|β| (Σ|q| + max|β|) × _ROUNDING.
    """
    n = weights.shape[0]
    out = np.zeros(2 * n - 1)
    tol = 0.0
    for axis in range(3):
        q = dc[:n, column + axis].copy()
        if axis == 2:
            q[0] += lift
        beta = to_bernstein(bern, q)
        top = np.max(np.abs(beta))
        tol += _ROUNDING * top * (np.sum(np.abs(q)) + top)
        for i in range(n):
            for j in range(n):
                out[i + j] += weights[i, j] * beta[i] * beta[j]
    return out, tol
