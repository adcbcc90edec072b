"""Solving the batch refinement's normal equations: block tridiagonal with a dense border.

The matrix (Jacobian's JᵀJ plus damping) of `mavsysid.estimation.batch` has, for K nodes of
12 unknowns and 6 θ unknowns,

    ⎡ D₀  U₀           B₀ ⎤
    ⎢ U₀ᵀ D₁  U₁       B₁ ⎥
    ⎢     ⋱   ⋱   ⋱    ⋮  ⎥
    ⎣ B₀ᵀ B₁ᵀ  …  T       ⎦

A block Cholesky factorisation in that order creates no fill: O(K·12³) work and memory,
against a general sparse LU (SuperLU) whose ordering and fill dominated the refinement's
run time. The θ block of the inverse, the θ covariance, is the inverse of the last Schur
complement, which the factorisation yields for free. Jacobi scaling to a unit diagonal
first: tiny process noise makes the defect weights huge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["BlockSystem", "ThetaBorderedFactor", "factor"]


@dataclass(frozen=True)
class BlockSystem:
    """A symmetric block tridiagonal matrix with a θ border, and a right-hand side.

    Attributes
    ----------
    D : ndarray, shape (K, 12, 12)
        Diagonal node blocks.
    U : ndarray, shape (max(K-1, 1), 12, 12)
        Blocks (k, k+1).
    B : ndarray, shape (K, 12, 6)
        Node–θ blocks.
    T : ndarray, shape (6, 6)
        θ block.
    g : ndarray, shape (K, 12)
        Right-hand side (Jᵀr) of the nodes.
    gt : ndarray, shape (6,)
        Right-hand side of θ.
    """

    D: np.ndarray
    U: np.ndarray
    B: np.ndarray
    T: np.ndarray
    g: np.ndarray
    gt: np.ndarray

    @classmethod
    def zeros(cls, K: int) -> BlockSystem:
        """An all-zero system of K nodes."""
        return cls(np.zeros((K, 12, 12)), np.zeros((max(K - 1, 1), 12, 12)),
                   np.zeros((K, 12, 6)), np.zeros((6, 6)), np.zeros((K, 12)), np.zeros(6))

    def diagonal(self) -> tuple[np.ndarray, np.ndarray]:
        """The matrix diagonal: of the nodes (K, 12) and of θ (6,)."""
        return np.diagonal(self.D, axis1=1, axis2=2).copy(), np.diag(self.T).copy()

    def dense(self) -> np.ndarray:
        """The full matrix (12K + 6 square); for tests on small systems."""
        K = self.D.shape[0]
        A = np.zeros((12 * K + 6, 12 * K + 6))
        for k in range(K):
            A[12 * k:12 * k + 12, 12 * k:12 * k + 12] = self.D[k]
            A[12 * k:12 * k + 12, 12 * K:] = self.B[k]
            A[12 * K:, 12 * k:12 * k + 12] = self.B[k].T
            if k < K - 1:
                A[12 * k:12 * k + 12, 12 * k + 12:12 * k + 24] = self.U[k]
                A[12 * k + 12:12 * k + 24, 12 * k:12 * k + 12] = self.U[k].T
        A[12 * K:, 12 * K:] = self.T
        return A


@numba.njit(cache=True)
def _factor_kernel(D, U, B, T, dn, dt, lam, Linv, C, P):
    """Block Cholesky of the Jacobi-scaled matrix with λ·diag added; returns S (6, 6).

    Linv[k] = L_kk⁻¹, C[k] = L_{k+1,k}, P[k] = L_{θ,k}; S is the Schur complement of θ.
    Raises numba's LinAlgError if a block is not positive definite.
    """
    K = D.shape[0]
    S = T * np.outer(dt, dt)
    for j in range(6):
        S[j, j] += lam * max(T[j, j], 1e-12) * dt[j] * dt[j]
    for k in range(K):
        Dk = D[k] * np.outer(dn[k], dn[k])
        for j in range(12):
            Dk[j, j] += lam * max(D[k, j, j], 1e-12) * dn[k, j] * dn[k, j]
        Bt = np.ascontiguousarray((B[k] * np.outer(dn[k], dt)).T)
        if k > 0:
            Ct = np.ascontiguousarray(C[k - 1].T)
            Dk -= C[k - 1] @ Ct
            Bt -= P[k - 1] @ Ct
        Li = np.linalg.inv(np.linalg.cholesky(Dk))
        LiT = np.ascontiguousarray(Li.T)
        Linv[k] = Li
        P[k] = Bt @ LiT
        S -= P[k] @ np.ascontiguousarray(P[k].T)
        if k < K - 1:
            C[k] = np.ascontiguousarray((U[k] * np.outer(dn[k], dn[k + 1])).T) @ LiT
    return S


@numba.njit(cache=True)
def _solve_kernel(Linv, C, P, Lt_inv, bn, bt):
    """Solve L Lᵀ x = b with the factors of `_factor_kernel` (scaled units)."""
    K = Linv.shape[0]
    y = np.empty_like(bn)
    yt = bt.copy()
    for k in range(K):
        rhs = bn[k].copy()
        if k > 0:
            rhs -= C[k - 1] @ y[k - 1]
        y[k] = Linv[k] @ rhs
        yt -= P[k] @ y[k]
    xt = Lt_inv.T @ (Lt_inv @ yt)
    x = np.empty_like(bn)
    for k in range(K - 1, -1, -1):
        rhs = y[k] - xt @ P[k]
        if k < K - 1:
            rhs -= x[k + 1] @ C[k]
        x[k] = rhs @ Linv[k]
    return x, xt


class ThetaBorderedFactor:
    """The factorisation of a `BlockSystem`'s matrix plus λ·diag(matrix) (LM damping).

    Parameters
    ----------
    system : BlockSystem
    lam : float
        Levenberg–Marquardt damping, relative to the diagonal (floored at 1e-12).

    Raises
    ------
    numpy.linalg.LinAlgError
        The damped matrix is not positive definite.
    """

    def __init__(self, system: BlockSystem, lam: float = 0.0) -> None:
        K = system.D.shape[0]
        diag_n, diag_t = system.diagonal()
        self.dn = 1.0 / np.sqrt(np.maximum(diag_n, 1e-300))
        self.dt = 1.0 / np.sqrt(np.maximum(diag_t, 1e-300))
        self.Linv = np.empty((K, 12, 12))
        self.C = np.empty((max(K - 1, 1), 12, 12))
        self.P = np.empty((K, 6, 12))
        S = _factor_kernel(system.D, system.U, system.B, system.T, self.dn, self.dt, lam,
                           self.Linv, self.C, self.P)
        self.Lt_inv = np.linalg.inv(np.linalg.cholesky(S))
        self.schur_scaled = S

    def solve(self, bn: np.ndarray, bt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x with A x = b: nodes (K, 12) and θ (6,), for b given as ``bn`` (K, 12), ``bt`` (6,)."""
        x, xt = _solve_kernel(self.Linv, self.C, self.P, self.Lt_inv, bn * self.dn, bt * self.dt)
        return x * self.dn, xt * self.dt

    def theta_inverse(self) -> np.ndarray:
        """The θ block (6, 6) of the matrix's inverse: the inverse Schur complement."""
        inv_scaled = self.Lt_inv.T @ self.Lt_inv
        return inv_scaled * np.outer(self.dt, self.dt)


def factor(system: BlockSystem, lam: float = 0.0) -> ThetaBorderedFactor:
    """Factor ``system``'s matrix + λ·diag; see `ThetaBorderedFactor`."""
    return ThetaBorderedFactor(system, lam)
