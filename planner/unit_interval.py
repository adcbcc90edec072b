"""The minimum-snap problem on the unit interval: the matrices every segment shares.

The closed form is Richter et al. (2013): with the boundary derivatives d = A c of the
coefficients c and the cost cᵀ Q c, the free part of d minimises dᵀ A⁻ᵀ Q A⁻¹ d. Time is
nondimensionalised, s = τ / T ∈ [0, 1], before solving: with b_j = c_j T^j and
d^k p/dτ^k = T^(-k) d^k p/ds^k, every matrix of the problem is the one of the unit
interval, so they are computed once at import and each connection is a small matrix
product. This is also what keeps T = 0.1 s and T = 10 s equally well conditioned.
"""

from __future__ import annotations

from math import factorial

import numpy as np

__all__ = [
    "DERIVATIVE_MAP", "POSITION_COEFFS", "POSITION_COST", "POSITION_DERIVS", "POSITION_FREE_END",
    "POSITION_HERMITE", "POWERS", "YAW_COEFFS", "YAW_COST", "YAW_DERIVS", "YAW_FREE_END",
    "YAW_HERMITE",
]

#: Coefficients per position axis (degree 9: continuity up to snap at both ends).
POSITION_COEFFS = 10
#: Coefficients of the yaw polynomial (degree 5: continuity up to yaw acceleration).
YAW_COEFFS = 6
#: Derivatives fixed at each end of a position axis: position … snap.
POSITION_DERIVS = POSITION_COEFFS // 2
#: Derivatives fixed at each end in yaw: yaw, yaw rate, yaw acceleration.
YAW_DERIVS = YAW_COEFFS // 2
_SNAP = 4  # derivative order minimised in position
_YAW_RATE = 1  # derivative order minimised in yaw


def _derivative_factors(n_coeffs: int, order: int) -> np.ndarray:
    """j!/(j-k)! for j = 0…N-1 (zero below the order), shape (N,)."""
    return np.array(
        [factorial(j) / factorial(j - order) if j >= order else 0.0 for j in range(n_coeffs)]
    )


def _boundary_matrix(n_coeffs: int) -> np.ndarray:
    """A of the unit interval: rows d^k/ds^k at s = 0, then at s = 1, k < N/2."""
    m = n_coeffs // 2
    at_zero = [np.eye(n_coeffs)[k] * factorial(k) for k in range(m)]
    at_one = [_derivative_factors(n_coeffs, k) for k in range(m)]
    return np.array(at_zero + at_one)


def _cost_matrix(n_coeffs: int, order: int) -> np.ndarray:
    """Q of the unit interval: bᵀ Q b = ∫₀¹ (d^r p/ds^r)² ds for r = ``order``."""
    f = _derivative_factors(n_coeffs, order)
    j = np.arange(n_coeffs)
    power = j[:, None] + j[None, :] - 2 * order + 1
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.outer(f, f) / power
    return np.where(np.outer(f, f) != 0.0, q, 0.0)


def _free_end_map(n_coeffs: int, order: int) -> np.ndarray:
    """M with b = M [d_start (N/2); p_end], the end derivatives chosen optimally.

    Richter et al. (2013): R = A⁻ᵀ Q A⁻¹, d_P* = -R_PP⁻¹ R_PF d_F, b = A⁻¹ [d_F; d_P*],
    with d_F the start derivatives and the end value and d_P the end derivatives.
    """
    m = n_coeffs // 2
    a_inv = np.linalg.inv(_boundary_matrix(n_coeffs))
    r = a_inv.T @ _cost_matrix(n_coeffs, order) @ a_inv
    fixed, free = np.arange(m + 1), np.arange(m + 1, n_coeffs)
    d_free = -np.linalg.solve(r[np.ix_(free, free)], r[np.ix_(free, fixed)])
    return a_inv[:, fixed] + a_inv[:, free] @ d_free


# Constant unit-interval matrices (the only part of the problem that can be cached):
# Hermite interpolation A⁻¹, the free-end map M, the cost Q, and the powers 0…N-1.
POSITION_HERMITE = np.linalg.inv(_boundary_matrix(POSITION_COEFFS))
YAW_HERMITE = np.linalg.inv(_boundary_matrix(YAW_COEFFS))
POSITION_FREE_END = _free_end_map(POSITION_COEFFS, _SNAP)
YAW_FREE_END = _free_end_map(YAW_COEFFS, _YAW_RATE)
POSITION_COST = _cost_matrix(POSITION_COEFFS, _SNAP)
YAW_COST = _cost_matrix(YAW_COEFFS, _YAW_RATE)
POWERS = np.arange(POSITION_COEFFS)


def _derivative_map() -> np.ndarray:
    """W with (W c).reshape(10, 18) · T^i = `Segment.derivative_coeffs`, shape (180, 36).

    The k-th τ-derivative of Σ c_j τ^j, written in s = τ/T, has the coefficient
    c_(i+k) (i+k)!/i! T^i at s^i; c stacks the x, y, z and yaw coefficients.
    """
    w = np.zeros((POSITION_COEFFS, 3 * POSITION_DERIVS + YAW_DERIVS,
                  3 * POSITION_COEFFS + YAW_COEFFS))
    columns = [(3 * k + a, POSITION_COEFFS * a, POSITION_COEFFS, k)
               for k in range(POSITION_DERIVS) for a in range(3)]
    columns += [(3 * POSITION_DERIVS + k, 3 * POSITION_COEFFS, YAW_COEFFS, k) for k in range(3)]
    for column, offset, n, k in columns:
        for i in range(n - k):
            w[i, column, offset + i + k] = factorial(i + k) / factorial(i)
    return w.reshape(-1, w.shape[-1])


#: W of `_derivative_map`: unit-time coefficients to `Segment.derivative_coeffs`.
DERIVATIVE_MAP = _derivative_map()
