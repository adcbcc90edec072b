"""Compiled kernels of the batch refinement: state ⊞/⊟, the shooting residuals, Jacobian and
normal equations, and their block solve.

The unknowns are the 12-D error of each shooting node and the scaled error of the P
estimated quantities. The Jacobian rows of one sample touch node k and θ; the defect
between node k and k+1 touches nodes k, k+1 and θ. So JᵀJ is block tridiagonal in the
nodes with a dense θ border:

    ⎡ D₀  U₀           B₀ ⎤
    ⎢ U₀ᵀ D₁  U₁       B₁ ⎥
    ⎢     ⋱   ⋱   ⋱    ⋮  ⎥
    ⎣ B₀ᵀ B₁ᵀ  …  T       ⎦

`shoot_kernel` accumulates those blocks directly (``mode`` 2) instead of building J as a
sparse matrix (``mode`` 1 still gives J in COO form, for `scipy.optimize.least_squares`
and the tests). A block Cholesky factorisation in that order (`ThetaBorderedFactor`)
creates no fill: O(K·12³) work and memory. The θ block of the inverse, the θ covariance,
is the inverse of the last Schur complement, which the factorisation yields for free.
Jacobi scaling to a unit diagonal keeps it well conditioned.

The σ inflation (`mavsysid.estimation.robust`) needs, at the optimum, Jᵀ E for a few
white probe columns E (``mode`` 2 adds it to the normal equations' pass) and each time
sample's share of (J X)ᵀ r for the columns X of H⁻¹ (``mode`` 3): both from the blocks as
they are formed, never J itself (as a sparse matrix, J of a 60 s flight at 500 Hz holds
4 million entries and its products took a third of the refinement's time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.vehicle.covariance import (
    MEASURED_ERROR_INDICES,
    pose_residual_kernel,
    predict_covariance_kernel,
)
from mavsysid.vehicle.dynamics import rk4_linear_step_kernel
from mavsysid.vehicle.linearization import (
    extra_columns_kernel,
    extra_wrench_kernel,
    jacobian_kernel,
    transition_kernel,
)
from mavsysid.vehicle.rotation import exp_kernel, log_kernel, multiply_kernel

__all__ = ["MODE_COO", "MODE_INFLUENCE", "MODE_NORMAL", "MODE_RESIDUALS", "BlockSystem",
           "ThetaBorderedFactor", "accumulate_kernel", "difference_kernel", "factor",
           "inject_kernel", "shoot_kernel", "whiten_kernel"]


@dataclass(frozen=True)
class BlockSystem:
    """A symmetric block tridiagonal matrix with a θ border, and a right-hand side.

    Attributes
    ----------
    D : ndarray, shape (K, 12, 12)
        Diagonal node blocks.
    U : ndarray, shape (max(K-1, 1), 12, 12)
        Blocks (k, k+1).
    B : ndarray, shape (K, 12, P)
        Node–θ blocks (θ: the P estimated quantities).
    T : ndarray, shape (P, P)
        θ block.
    g : ndarray, shape (K, 12)
        Right-hand side (Jᵀr) of the nodes.
    gt : ndarray, shape (P,)
        Right-hand side of θ.
    """

    D: np.ndarray
    U: np.ndarray
    B: np.ndarray
    T: np.ndarray
    g: np.ndarray
    gt: np.ndarray

    @classmethod
    def zeros(cls, K: int, parameters: int = 6) -> BlockSystem:
        """An all-zero system of K nodes and ``parameters`` quantities."""
        p = parameters
        return cls(np.zeros((K, 12, 12)), np.zeros((max(K - 1, 1), 12, 12)),
                   np.zeros((K, 12, p)), np.zeros((p, p)), np.zeros((K, 12)), np.zeros(p))

    def diagonal(self) -> tuple[np.ndarray, np.ndarray]:
        """The matrix diagonal: of the nodes (K, 12) and of θ (P,)."""
        return np.diagonal(self.D, axis1=1, axis2=2).copy(), np.diag(self.T).copy()

    def dense(self) -> np.ndarray:
        """The full matrix (12K + P square); for tests on small systems."""
        K, p = self.D.shape[0], self.T.shape[0]
        A = np.zeros((12 * K + p, 12 * K + p))
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
def _cholesky_inverse(A, Li):
    """Li = L⁻¹ of A = L Lᵀ (n, n), A's lower triangle overwritten by L; False if A is not
    positive definite.

    Written out for the 12 × 12 node blocks: LAPACK's per-call overhead, not the
    arithmetic, made up most of the factorisation's time.
    """
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for m in range(j):
            s -= A[j, m] * A[j, m]
        if not s > 0.0:
            return False
        A[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for m in range(j):
                s -= A[i, m] * A[j, m]
            A[i, j] = s / A[j, j]
    for j in range(n):
        Li[j, j] = 1.0 / A[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for m in range(j, i):
                s -= A[i, m] * Li[m, j]
            Li[i, j] = s / A[i, i]
        for i in range(j):
            Li[i, j] = 0.0
    return True


@numba.njit(cache=True)
def _eliminate(Dk, Bt, Cp, Pp):
    """Dk −= Cp Cpᵀ (lower triangle) and Bt −= Pp Cpᵀ: node k's blocks less node k − 1's."""
    for i in range(12):
        for j in range(i + 1):
            s = 0.0
            for m in range(12):
                s += Cp[i, m] * Cp[j, m]
            Dk[i, j] -= s
        for a in range(Bt.shape[0]):
            s = 0.0
            for m in range(12):
                s += Pp[a, m] * Cp[i, m]
            Bt[a, i] -= s


@numba.njit(cache=True)
def _factor_kernel(D, U, B, T, dn, dt, lam, Linv, C, P):
    """Block Cholesky of the Jacobi-scaled matrix with λ·diag added; returns S (P, P).

    Linv[k] = L_kk⁻¹, C[k] = L_{k+1,k}, P[k] = L_{θ,k}; S is the Schur complement of θ.
    Raises LinAlgError if a block is not positive definite.
    """
    K, p = D.shape[0], T.shape[0]
    S = T * np.outer(dt, dt)
    for j in range(p):
        S[j, j] += lam * max(T[j, j], 1e-12) * dt[j] * dt[j]
    Dk, Bt = np.empty((12, 12)), np.empty((p, 12))
    for k in range(K):
        for i in range(12):
            for j in range(12):
                Dk[i, j] = D[k, i, j] * dn[k, i] * dn[k, j]
            Dk[i, i] += lam * max(D[k, i, i], 1e-12) * dn[k, i] * dn[k, i]
            for a in range(p):
                Bt[a, i] = B[k, i, a] * dn[k, i] * dt[a]
        if k > 0:
            _eliminate(Dk, Bt, C[k - 1], P[k - 1])
        if not _cholesky_inverse(Dk, Linv[k]):
            raise np.linalg.LinAlgError("Matrix is not positive definite.")
        Li = Linv[k]
        for a in range(p):  # P[k] = Bt Liᵀ
            for i in range(12):
                s = 0.0
                for m in range(i + 1):
                    s += Bt[a, m] * Li[i, m]
                P[k, a, i] = s
        for a in range(p):  # S −= P[k] P[k]ᵀ
            for c in range(a + 1):
                s = 0.0
                for m in range(12):
                    s += P[k, a, m] * P[k, c, m]
                S[a, c] -= s
                if c != a:
                    S[c, a] -= s
        if k < K - 1:  # C[k] = (scaled U[k])ᵀ Liᵀ
            for i in range(12):
                for j in range(12):
                    s = 0.0
                    for m in range(j + 1):
                        s += U[k, m, i] * dn[k, m] * Li[j, m]
                    C[k, i, j] = s * dn[k + 1, i]
    return S


@numba.njit(cache=True)
def _solve_kernel(Linv, C, P, Lt_inv, bn, bt):
    """Solve L Lᵀ X = B with the factors of `_factor_kernel` (scaled units), for m
    right-hand sides at once: bn (K, 12, m), bt (P, m)."""
    K = Linv.shape[0]
    p, m = bt.shape
    y, yt = np.empty_like(bn), bt.copy()
    for k in range(K):
        for c in range(m):
            for i in range(12):
                s = bn[k, i, c]
                if k > 0:
                    for j in range(12):
                        s -= C[k - 1, i, j] * y[k - 1, j, c]
                y[k, i, c] = s
            for i in range(11, -1, -1):  # y ← L_kk⁻¹ y, lower triangular, from the bottom
                s = 0.0
                for j in range(i + 1):
                    s += Linv[k, i, j] * y[k, j, c]
                y[k, i, c] = s
            for a in range(p):
                s = 0.0
                for j in range(12):
                    s += P[k, a, j] * y[k, j, c]
                yt[a, c] -= s
    xt = np.ascontiguousarray(Lt_inv.T) @ (Lt_inv @ yt)
    x, r = np.empty_like(bn), np.empty(12)
    for k in range(K - 1, -1, -1):
        for c in range(m):
            for i in range(12):
                s = y[k, i, c]
                for a in range(p):
                    s -= P[k, a, i] * xt[a, c]
                if k < K - 1:
                    for j in range(12):
                        s -= C[k, j, i] * x[k + 1, j, c]
                r[i] = s
            for i in range(12):  # x = L_kk⁻ᵀ r
                s = 0.0
                for j in range(i, 12):
                    s += Linv[k, j, i] * r[j]
                x[k, i, c] = s
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
        self.P = np.empty((K, system.T.shape[0], 12))
        S = _factor_kernel(system.D, system.U, system.B, system.T, self.dn, self.dt, lam,
                           self.Linv, self.C, self.P)
        self.Lt_inv = np.linalg.inv(np.linalg.cholesky(S))
        self.schur_scaled = S

    def solve(self, bn: np.ndarray, bt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x with A x = b: nodes (K, 12) and θ (P,), for b given as ``bn`` (K, 12), ``bt`` (P,);
        or m right-hand sides at once, ``bn`` (K, 12, m) and ``bt`` (P, m)."""
        many = bn.ndim == 3
        bn = bn if many else bn[:, :, None]
        bt = bt if many else bt[:, None]
        x, xt = _solve_kernel(self.Linv, self.C, self.P, self.Lt_inv,
                              np.ascontiguousarray(bn * self.dn[:, :, None]),
                              np.ascontiguousarray(bt * self.dt[:, None]))
        x, xt = x * self.dn[:, :, None], xt * self.dt[:, None]
        return (x, xt) if many else (x[:, :, 0], xt[:, 0])

    def theta_inverse(self) -> np.ndarray:
        """The θ block (P, P) of the matrix's inverse: the inverse Schur complement."""
        inv_scaled = self.Lt_inv.T @ self.Lt_inv
        return inv_scaled * np.outer(self.dt, self.dt)


def factor(system: BlockSystem, lam: float = 0.0) -> ThetaBorderedFactor:
    """Factor ``system``'s matrix + λ·diag; see `ThetaBorderedFactor`."""
    return ThetaBorderedFactor(system, lam)


#: ``shoot_kernel`` modes: residuals only; with J in COO form; with JᵀJ and Jᵀr in blocks
#: (and Jᵀ E for probe columns E); each time sample's share of (J X)ᵀ r.
MODE_RESIDUALS, MODE_COO, MODE_NORMAL, MODE_INFLUENCE = 0, 1, 2, 3


@numba.njit(cache=True)
def whiten_kernel(Q, W):
    """W with Wᵀ W = Q⁻¹ for one block Q, robust to a singular Q.

    Parameters
    ----------
    Q : ndarray, shape (12, 12)
        A defect's covariance (the process noise over a node interval).
    W : ndarray, shape (12, 12)
        Receives the inverse Cholesky factor of Q, symmetrised and lifted by 10⁻⁹ of its
        mean diagonal (and 10⁻¹²).
    """
    q = 0.5 * (Q + Q.T) + np.eye(12) * (1e-12 + 1e-9 * np.trace(Q) / 12)
    W[:] = np.linalg.inv(np.linalg.cholesky(q))


@numba.njit(cache=True)
def inject_kernel(x, d, out):
    """out = x ⊞ d for a model state x (13,) and a 12-D error d."""
    out[0:6] = x[0:6] + d[0:6]
    q = multiply_kernel(x[6:10], exp_kernel(d[6:9]))
    out[6:10] = q / np.sqrt(np.sum(q * q))
    out[10:13] = x[10:13] + d[9:12]


@numba.njit(cache=True)
def difference_kernel(x, x_ref, out):
    """out = x ⊟ x_ref, 12-D."""
    out[0:6] = x[0:6] - x_ref[0:6]
    c = np.array([x_ref[6], -x_ref[7], -x_ref[8], -x_ref[9]])
    out[6:9] = log_kernel(multiply_kernel(c, x[6:10]))
    out[9:12] = x[10:13] - x_ref[10:13]


@numba.njit(cache=True)
def accumulate_kernel(Jr, r, m, ncols, k, D, U, B, T, g, gt):
    """Add the rows Jr[:m, :ncols] (residuals r[:m]) to the blocks of JᵀJ and Jᵀr.

    Local columns: 0–11 node k, 12 … 11 + P θ, then node k+1 (only with ``ncols``
    24 + P). D (K, 12, 12) diagonal node blocks; U (K-1, 12, 12) the (k, k+1) blocks;
    B (K, 12, P) node–θ blocks; T (P, P) the θ block; g (K, 12) and gt (P,) Jᵀr.
    """
    p = T.shape[0]
    e = 12 + p
    J = np.ascontiguousarray(Jr[:m, :ncols])
    Jt = np.ascontiguousarray(J.T)
    M = Jt @ J
    v = Jt @ np.ascontiguousarray(r[:m])
    D[k] += M[0:12, 0:12]
    B[k] += M[0:12, 12:e]
    T += M[12:e, 12:e]
    g[k] += v[0:12]
    gt += v[12:e]
    if ncols > e:
        U[k] += M[0:12, e:e + 12]
        B[k + 1] += M[e:e + 12, 12:e]
        D[k + 1] += M[e:e + 12, e:e + 12]
        g[k + 1] += v[e:e + 12]


@numba.njit(cache=True)
def _write_coo(Jr, m, ncols, p, row, k, th_col, rows, cols, vals, e):
    for a in range(m):
        for b in range(ncols):
            rows[e] = row + a
            if b < 12:
                cols[e] = 12 * k + b
            elif b < 12 + p:
                cols[e] = th_col + b - 12
            else:
                cols[e] = 12 * (k + 1) + b - 12 - p
            vals[e] = Jr[a, b]
            e += 1
    return e


@numba.njit(cache=True)
def _pose_rows(Phi, sig_p, sig_a, Jr):
    """Jr's first 6 rows: −H Φ of the measured error-state entries, whitened."""
    for a in range(6):
        s = sig_p if a < 3 else sig_a
        for b in range(Phi.shape[1]):
            Jr[a, b] = -Phi[MEASURED_ERROR_INDICES[a], b] / s


@numba.njit(cache=True)
def _accumulate_at_node(res, row, sig_p, sig_a, k, D, g, E, Etn):
    """The pose rows of node k's own sample (Φ = I, so J = −H/σ) into D[k], g[k], Jᵀ E."""
    for a in range(6):
        s = sig_p if a < 3 else sig_a
        j = MEASURED_ERROR_INDICES[a]
        D[k, j, j] += 1.0 / (s * s)
        g[k, j] -= res[row + a] / s
        for i in range(E.shape[1]):
            Etn[k, j, i] -= E[row + a, i] / s


@numba.njit(cache=True)
def _accumulate_defect(W, Phi, r, E, row, k, normal, probe):
    """Interval k's defect rows J = [−W Φ₁₂ | W] (node k and θ, node k+1) with residuals r
    (12,) into the normal equations and Jᵀ E, through M = Wᵀ W.

    JᵀJ's blocks are Φᵀ M Φ, −Φᵀ M and M, and Jᵀ r is [−Φᵀ; I] Wᵀ r: about half the
    products of forming J's 12 × (24 + P) rows and multiplying them out.
    """
    D, U, B, T, g, gt = normal
    _, Etn, Ett = probe
    p = T.shape[0]
    dim = 12 + p
    M, MPhi, Wr = np.empty((12, 12)), np.empty((12, dim)), np.empty(12)
    for i in range(12):
        for j in range(i + 1):
            s = 0.0
            for m in range(12):
                s += W[m, i] * W[m, j]
            M[i, j] = s
            M[j, i] = s
        s = 0.0
        for m in range(12):
            s += W[m, i] * r[m]
        Wr[i] = s
    for i in range(12):
        for c in range(dim):
            s = 0.0
            for j in range(12):
                s += M[i, j] * Phi[j, c]
            MPhi[i, c] = s
    for i in range(dim):  # Φᵀ M Φ: node k (D, B) and θ (T); Φᵀ Wᵀ r
        for c in range(i, dim):
            s = 0.0
            for j in range(12):
                s += Phi[j, i] * MPhi[j, c]
            if c < 12:
                D[k, i, c] += s
                if c != i:
                    D[k, c, i] += s
            elif i < 12:
                B[k, i, c - 12] += s
            else:
                T[i - 12, c - 12] += s
                if c != i:
                    T[c - 12, i - 12] += s
        s = 0.0
        for j in range(12):
            s += Phi[j, i] * Wr[j]
        if i < 12:
            g[k, i] -= s
        else:
            gt[i - 12] -= s
    for i in range(12):  # −Φᵀ M into U[k] and B[k+1]; M and Wᵀ r into node k+1
        for c in range(12):
            U[k, i, c] -= MPhi[c, i]
            D[k + 1, i, c] += M[i, c]
        for a in range(p):
            B[k + 1, i, a] -= MPhi[i, 12 + a]
        g[k + 1, i] += Wr[i]
    if E.shape[1]:
        _probe_defect(W, Phi, E, row, k, Etn, Ett)


@numba.njit(cache=True)
def _probe_defect(W, Phi, E, row, k, Etn, Ett):
    """The defect rows' share of Jᵀ E: [−Φᵀ; I] Wᵀ E (E's rows from ``row``)."""
    p, d = Ett.shape
    WE = np.empty((12, d))
    for i in range(12):
        for e in range(d):
            s = 0.0
            for m in range(12):
                s += W[m, i] * E[row + m, e]
            WE[i, e] = s
            Etn[k + 1, i, e] += s
    for i in range(12 + p):
        for e in range(d):
            s = 0.0
            for j in range(12):
                s += Phi[j, i] * WE[j, e]
            if i < 12:
                Etn[k, i, e] -= s
            else:
                Ett[i - 12, e] -= s


@numba.njit(cache=True)
def _probe_rows(Jr, m, ncols, row, k, E, Etn, Ett):
    """Add the rows' share of Jᵀ E (E's rows from ``row``) to Etn[k] (Etn[k+1]) and Ett."""
    p = Ett.shape[0]
    JtE = np.ascontiguousarray(Jr[:m, :ncols].T) @ np.ascontiguousarray(E[row:row + m])
    Etn[k] += JtE[0:12]
    Ett += JtE[12:12 + p]
    if ncols > 12 + p:
        Etn[k + 1] += JtE[12 + p:]


@numba.njit(cache=True)
def _influence_rows(Jr, m, ncols, row, k, sample, res, E, Xn, Xt, data, white):
    """Time sample ``sample``'s share of (J X)ᵀ r, for X's first P columns (H⁻¹ of the P
    quantities) with the residuals r into ``data`` (n, P), and with each probe's white
    residual E_i − (J Z)_i (Z: X's other columns) into ``white`` (probes, n, P)."""
    p = data.shape[1]
    X = np.empty((ncols, Xt.shape[1]))
    X[0:12] = Xn[k]
    X[12:12 + p] = Xt
    if ncols > 12 + p:
        X[12 + p:] = Xn[k + 1]
    G = np.ascontiguousarray(Jr[:m, :ncols]) @ X
    for a in range(m):
        for c in range(p):
            data[sample, c] += G[a, c] * res[row + a]
        for i in range(E.shape[1]):
            w = E[row + a, i] - G[a, p + i]
            for c in range(p):
                white[i, sample, c] += G[a, c] * w


@numba.njit(cache=True)
def _row_group(Jr, m, ncols, row, k, sample, at_node, mode, res, sig, coo, e, normal, probe,
               influence):
    """Dispatch one group of m Jacobian rows (Jr[:m, :ncols]) of node k as ``mode`` asks;
    returns the COO entries written so far (``coo`` = (rows, cols, vals, θ's first column))."""
    if mode == MODE_COO:
        rows, cols, vals, th_col = coo
        return _write_coo(Jr, m, ncols, Jr.shape[1] - 24, row, k, th_col, rows, cols, vals, e)
    E, Etn, Ett = probe
    if mode == MODE_NORMAL:
        D, U, B, T, g, gt = normal
        if at_node:
            _accumulate_at_node(res, row, sig[0], sig[1], k, D, g, E, Etn)
            return e
        accumulate_kernel(Jr, res[row:row + m], m, ncols, k, D, U, B, T, g, gt)
        if E.shape[1]:
            _probe_rows(Jr, m, ncols, row, k, E, Etn, Ett)
        return e
    Xn, Xt, data, white = influence
    _influence_rows(Jr, m, ncols, row, k, sample, res, E, Xn, Xt, data, white)
    return e


@numba.njit(cache=True)
def _defect_rows(W, Phi, dim, Jr):
    """Jr's 12 defect rows: −W Φ (node k and θ columns), then W (node k+1's columns)."""
    WPhi = W @ np.ascontiguousarray(Phi[0:12, :])
    Jr[:, 0:dim] = -WPhi
    Jr[:, dim:dim + 12] = W


@numba.njit(cache=True)
def shoot_kernel(nodes, theta, t, z, n, w, basis, node_idx, mass, r, eps, scale, Qc, W, sig,
                 mode, want_q, set_w, res, Q_out, coo, normal, probe, influence):
    """Residuals of the shooting problem, and from its Jacobian what ``mode`` asks.

    w (N, 6): the known effects' wrench per sample (as in the EKF); basis (N, 6, E): the
    nuisance quantities' wrench per unit value; Qc (N, 6, 6): the process-noise density of
    each step; θ: P quantities; sig: the pose σ (m, rad). J's columns: node k's error at
    12k … 12k+11, the scaled θ error at 12K … 12K+P−1. ``mode`` 1 writes J as COO into
    ``coo`` = (rows, cols, vals, 12K); ``mode`` 2 adds JᵀJ and Jᵀr into ``normal`` = (D, U, B,
    T, g, gt) (`accumulate_kernel`; zero them first) and Jᵀ E into ``probe`` = (E (M, d),
    Etn (K, 12, d), Ett (P, d)) for d probe columns (d may be 0); ``mode`` 3 adds each time
    sample's share of (J X)ᵀ r into ``influence`` = (Xn (K, 12, P + d), Xt (P, P + d),
    data, white) (`_influence_rows`; a defect counts with its interval's last sample).
    ``Q_out`` (K-1, 12, 12) receives each interval's process noise if ``want_q``; W[k] is
    set to its whitening (`whiten_kernel`) before its defect is formed if ``set_w``.
    Returns the number of residual rows and of COO entries written.
    """
    K, p = nodes.shape[0], theta.shape[0]
    dim, row, e = 12 + p, 0, 0
    A, G, F, Qs = (np.empty((dim, dim)), np.empty((dim, 6)), np.empty((dim, dim)),
                   np.empty((dim, dim)))
    x, x_next, y, d = np.empty(13), np.empty(13), np.empty(6), np.empty(12)
    wa, wb = np.empty(6), np.empty(6)
    Jr = np.zeros((12, dim + 12))
    want_jac, noise = mode != MODE_RESIDUALS, want_q or set_w
    for k in range(K):
        x[:] = nodes[k]
        Phi, Qacc = np.eye(dim), np.zeros((dim, dim))
        last = node_idx[k + 1] if k < K - 1 else node_idx[K] - 1
        for i in range(node_idx[k], last + 1):
            first = i == node_idx[k]  # Phi = I and Qacc = 0 so far
            if i < node_idx[k + 1]:  # measurement at sample i
                pose_residual_kernel(z[i], x, y)
                res[row:row + 3] = y[0:3] / sig[0]
                res[row + 3:row + 6] = y[3:6] / sig[1]
                if want_jac:
                    _pose_rows(Phi, sig[0], sig[1], Jr)
                    e = _row_group(Jr, 6, dim, row, k, i, first, mode, res, sig, coo, e, normal,
                                   probe, influence)
                row += 6
            if i == last:
                break
            if want_jac or (noise and k < K - 1):
                jacobian_kernel(x, n[i], theta, mass, r, eps, scale, A, G)
                extra_columns_kernel(basis[i], theta[3:6], mass, scale, A)
                transition_kernel(A, G, Qc[i], t[i + 1] - t[i], F, Qs)
                Phi = F.copy() if first else F @ Phi
                if noise:  # the process noise accumulated since the node (paper Eq. prior)
                    if first:
                        Qacc[:] = Qs
                    else:
                        predict_covariance_kernel(Qacc, F, Qs)
            extra_wrench_kernel(w[i], basis[i], theta[6:], wa)
            extra_wrench_kernel(w[i + 1], basis[i + 1], theta[6:], wb)
            rk4_linear_step_kernel(x, n[i], n[i + 1], wa, wb, theta, t[i + 1] - t[i], mass, r,
                                   eps, x_next)
            x[:] = x_next
        if k < K - 1:
            if want_q:
                Q_out[k] = Qacc[0:12, 0:12]
            if set_w:
                whiten_kernel(Qacc[0:12, 0:12], W[k])
            difference_kernel(nodes[k + 1], x, d)
            res[row:row + 12] = W[k] @ d
            if mode == MODE_NORMAL:
                _accumulate_defect(W[k], Phi, res[row:row + 12], probe[0], row, k, normal,
                                   probe)
            elif want_jac:
                _defect_rows(W[k], Phi, dim, Jr)
                e = _row_group(Jr, 12, dim + 12, row, k, node_idx[k + 1] - 1, False, mode, res,
                               sig, coo, e, normal, probe, influence)
            row += 12
    return row, e
