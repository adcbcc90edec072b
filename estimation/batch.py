"""Batch maximum-a-posteriori refinement: states and θ jointly over the whole flight.

In the spirit of Burri et al.'s maximum-likelihood identification, and because the paper
found its EKF overconfident on real flights, the filter's estimate is refined by a
batch MAP over states and θ jointly, posed as multiple shooting: nodes at every sample
by default (or every ``node_interval`` seconds); the unknowns are the model state at each
node (as a 12-D error of the filtered state) and θ (as a scaled error). The cost is

    Σ_samples |pose residual / σ|²  +  Σ_nodes |W_k (x_{k+1} ⊟ Φ(x_k, θ))|²  +  |θ prior|²,

where Φ integrates the model (RK4, logged rotor speeds) from one node to the next and
W_k whitens the defect with the process noise accumulated over the interval (the model's
Q, at the level the caller chose, e.g. fitted by `mavsysid.estimation.noise_fit`). Unlike a pure
output-error fit, the defects let the states follow the data, so a 30 s flight does not
drift. Levenberg–Marquardt with a sparse Jacobian built from the shared linearisation
(transition matrices along each interval) and a sparse direct solve; the θ covariance is
the θ block of (JᵀJ)⁻¹ at the optimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mavsysid.estimation.ekf import rk4_step_kernel
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.input_noise import step_process_noise
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.linearization import ErrorStateModel, jacobian_kernel, transition_kernel
from mavsysid.vehicle.rotation import exp_kernel, log_kernel, multiply_kernel

__all__ = ["BatchResult", "refine"]


@dataclass(frozen=True)
class BatchResult:
    """The refined estimate and how the optimisation went.

    Attributes
    ----------
    estimate : ParameterEstimate
        θ and its covariance, SI.
    states : ndarray, shape (K, 13)
        Refined model states at the nodes.
    node_times : ndarray, shape (K,)
        s.
    iterations : int
    cost_initial, cost_final : float
        ½ Σ r² at the filter's estimate and at the optimum.
    """

    estimate: ParameterEstimate
    states: np.ndarray
    node_times: np.ndarray
    iterations: int
    cost_initial: float
    cost_final: float


@numba.njit(cache=True)
def _inject_kernel(x, d, out):
    """out = x ⊞ d for a model state x (13,) and a 12-D error d."""
    out[0:6] = x[0:6] + d[0:6]
    q = multiply_kernel(x[6:10], exp_kernel(d[6:9]))
    out[6:10] = q / np.sqrt(np.sum(q * q))
    out[10:13] = x[10:13] + d[9:12]


@numba.njit(cache=True)
def _difference_kernel(x, x_ref, out):
    """out = x ⊟ x_ref, 12-D."""
    out[0:6] = x[0:6] - x_ref[0:6]
    c = np.array([x_ref[6], -x_ref[7], -x_ref[8], -x_ref[9]])
    out[6:9] = log_kernel(multiply_kernel(c, x[6:10]))
    out[9:12] = x[10:13] - x_ref[10:13]


@numba.njit(cache=True)
def _shoot(nodes, theta, t, z, n, w, node_idx, mass, r, eps, scale, Qc, W, sig_p, sig_a,
           want_jac, want_q, res, rows, cols, vals, Q_out):
    """Residuals of the shooting problem (and its Jacobian in COO form if ``want_jac``).

    w (N, 6) is the known effects' extra body force and torque per sample (as in the EKF);
    Qc (N, 6, 6) the process-noise density of the step from each sample to the next.

    Column layout: node k's error at 12k … 12k+11, the θ error (scaled) at 12K … 12K+5.
    ``Q_out`` (K-1, 12, 12) receives the process noise accumulated over each interval.
    """
    K = nodes.shape[0]
    th_col = 12 * K
    row = 0
    e = 0
    A = np.empty((18, 18))
    G = np.empty((18, 6))
    F = np.empty((18, 18))
    Qs = np.empty((18, 18))
    x = np.empty(13)
    x_next = np.empty(13)
    d = np.empty(12)
    for k in range(K):
        x[:] = nodes[k]
        Phi = np.eye(18)
        Qacc = np.zeros((18, 18))
        last = node_idx[k + 1] if k < K - 1 else node_idx[K] - 1
        for i in range(node_idx[k], last + 1):
            if i < node_idx[k + 1]:  # measurement at sample i
                res[row:row + 3] = (z[i, 0:3] - x[0:3]) / sig_p
                c = np.array([x[6], -x[7], -x[8], -x[9]])
                res[row + 3:row + 6] = log_kernel(multiply_kernel(c, z[i, 3:7])) / sig_a
                if want_jac:
                    for a in range(6):
                        src = a if a < 3 else a + 3
                        s = sig_p if a < 3 else sig_a
                        for b in range(18):
                            rows[e] = row + a
                            cols[e] = 12 * k + b if b < 12 else th_col + b - 12
                            vals[e] = -Phi[src, b] / s
                            e += 1
                row += 6
            if i == last:
                break
            dt = t[i + 1] - t[i]
            if want_jac or (want_q and k < K - 1):
                jacobian_kernel(x, n[i], theta, mass, r, eps, scale, A, G)
                transition_kernel(A, G, Qc[i], dt, F, Qs)
                Phi = F @ Phi
                Qacc = F @ Qacc @ F.T + Qs
            rk4_step_kernel(x, n[i], n[i + 1], w[i], w[i + 1], theta, dt, mass, r, eps, x_next)
            x[:] = x_next
        if k < K - 1:
            if want_q:
                Q_out[k] = Qacc[0:12, 0:12]
            _difference_kernel(nodes[k + 1], x, d)
            res[row:row + 12] = W[k] @ d
            if want_jac:
                WPhi = W[k] @ np.ascontiguousarray(Phi[0:12, :])
                for a in range(12):
                    for b in range(12):
                        rows[e] = row + a
                        cols[e] = 12 * (k + 1) + b
                        vals[e] = W[k, a, b]
                        e += 1
                    for b in range(18):
                        rows[e] = row + a
                        cols[e] = 12 * k + b if b < 12 else th_col + b - 12
                        vals[e] = -WPhi[a, b]
                        e += 1
            row += 12
    return row, e


@dataclass
class _Problem:
    flight: FlightData
    model: ErrorStateModel
    node_idx: np.ndarray
    prior: ParameterEstimate
    sigma: tuple[float, float]
    W: np.ndarray
    wrench: np.ndarray | None = None

    def evaluate(
        self, nodes: np.ndarray, theta: np.ndarray, want_jac: bool, want_q: bool = False
    ) -> tuple[np.ndarray, sp.csr_matrix | None, np.ndarray]:
        fl = self.flight
        K = nodes.shape[0]
        n_meas = len(fl)
        m = 6 * n_meas + 12 * (K - 1)
        nnz = (6 * 18 * n_meas + 12 * 30 * (K - 1)) if want_jac else 1
        res = np.empty(m + 6)
        rows = np.empty(nnz, np.int64)
        cols = np.empty(nnz, np.int64)
        vals = np.empty(nnz)
        Q_out = np.empty((max(K - 1, 1), 12, 12))
        mass, r, eps, scale = self.model.kernel_args()
        _shoot(nodes, theta, self._t, self._z, self._n, self._w, self.node_idx, mass, r, eps,
               scale, self._Qc, self.W, self.sigma[0], self.sigma[1], want_jac, want_q, res, rows,
               cols, vals, Q_out)
        # Prior on θ, in the scaled units of the error state.
        prior_sigma = np.sqrt(np.diag(self.prior.covariance))
        res[m:] = (theta - self.prior.value) / prior_sigma
        if not want_jac:
            return res, None, Q_out
        th_col = 12 * K
        rows = np.concatenate([rows, m + np.arange(6)])
        cols = np.concatenate([cols, th_col + np.arange(6)])
        vals = np.concatenate([vals, scale / prior_sigma])
        J = sp.csr_matrix((vals, (rows, cols)), shape=(m + 6, th_col + 6))
        return res, J, Q_out

    def __post_init__(self) -> None:
        fl = self.flight
        self._t = np.ascontiguousarray(fl.t, dtype=float)
        self._z = np.ascontiguousarray(np.hstack([fl.position, fl.quaternion]))
        self._n = np.ascontiguousarray(fl.rotor_speeds, dtype=float)
        self._w = (np.zeros((len(fl), 6)) if self.wrench is None
                   else np.ascontiguousarray(self.wrench, dtype=float))
        # Each step's process noise, with the slow inputs' interpolation error.
        _, r, eps, _ = self.model.kernel_args()
        self._Qc = step_process_noise(self.model.process_noise_density(), self._t, self._n,
                                      fl.inputs, self.prior.value, r, eps)


def _solve_spd(A: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
    """Solve A x = b for a sparse symmetric positive definite A.

    Jacobi scaling to a unit diagonal, then SuperLU in symmetric mode without pivoting:
    an SPD matrix needs none, and pivoting on an ill-conditioned one (tiny process
    noise makes the defect weights huge) would destroy the fill-reducing ordering.
    """
    d = 1.0 / np.sqrt(A.diagonal())
    D = sp.diags(d)
    lu = spla.splu((D @ A @ D).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    x = lu.solve(b * (d[:, None] if b.ndim == 2 else d))
    return x * (d[:, None] if b.ndim == 2 else d)


def _whitening(Q: np.ndarray) -> np.ndarray:
    """W with Wᵀ W = Q⁻¹ for each (12, 12) block, robust to a singular Q."""
    W = np.empty_like(Q)
    for k, q in enumerate(Q):
        q = 0.5 * (q + q.T) + np.eye(12) * (1e-12 + 1e-9 * np.trace(q) / 12)
        L = np.linalg.cholesky(q)
        W[k] = np.linalg.inv(L)
    return W


def _apply(model: ErrorStateModel, nodes: np.ndarray, theta: np.ndarray, step: np.ndarray):
    K = nodes.shape[0]
    new_nodes = np.empty_like(nodes)
    for k in range(K):
        _inject_kernel(nodes[k], step[12 * k:12 * k + 12], new_nodes[k])
    return new_nodes, theta + model.theta_scale * step[12 * K:]


def _theta_covariance(J: sp.spmatrix, K: int, theta_scale: np.ndarray) -> np.ndarray:
    """θ covariance (6, 6), SI: the θ block of (JᵀJ)⁻¹ at the optimum, K shooting nodes."""
    JtJ = (J.T @ J).tocsc()
    E = np.zeros((JtJ.shape[0], 6))
    E[12 * K:, :] = np.eye(6)
    cov_scaled = _solve_spd(JtJ, E)[12 * K:, :]
    cov = np.asarray(cov_scaled) * np.outer(theta_scale, theta_scale)
    return 0.5 * (cov + cov.T)


def refine(
    flight: FlightData, filtered_states: np.ndarray, filtered: ParameterEstimate,
    model: ErrorStateModel, prior: ParameterEstimate, sigma: tuple[float, float],
    node_interval: float = 0.0, max_iterations: int = 30, wrench: np.ndarray | None = None,
) -> BatchResult:
    """Refine the filter's result by batch MAP over the whole flight.

    Parameters
    ----------
    flight : FlightData
    filtered_states : ndarray, shape (N, 13)
        The filter's states at every sample (the starting point).
    filtered : ParameterEstimate
        The filter's θ (the starting point).
    model : ErrorStateModel
        The shared linearisation (its θ scale sets the units of the θ unknowns).
    prior : ParameterEstimate
        The prior on θ, as given to the filter.
    sigma : tuple of 2 float
        Position σ (m) and attitude σ (rad) of the measurements.
    node_interval : float
        Time between shooting nodes, s; 0 (default) puts a node at every sample, which
        models the process noise inside every interval (full Gauss–Newton smoothing).
    max_iterations : int
    wrench : ndarray, shape (N, 6), optional
        Extra body force (N) and torque (N·m) of known model effects at every sample,
        held fixed (as given to the filter); zeros by default. ``flight`` must already be
        in the model's terms (`mavsysid.estimation.effect_channels.ModelTerms`).
    """
    dt = float(np.median(np.diff(flight.t)))
    step = max(1, round(node_interval / dt))
    node_idx = np.append(np.arange(0, len(flight) - 1, step), len(flight)).astype(np.int64)
    nodes = np.ascontiguousarray(filtered_states[node_idx[:-1]])
    theta = filtered.value.copy()
    K = nodes.shape[0]
    problem = _Problem(flight, model, node_idx, prior, sigma, np.zeros((max(K - 1, 1), 12, 12)),
                       wrench)
    _, _, Q_int = problem.evaluate(nodes, theta, want_jac=False, want_q=True)
    problem.W = _whitening(Q_int)

    res, J, _ = problem.evaluate(nodes, theta, want_jac=True)
    cost0 = cost = 0.5 * float(res @ res)
    lam = 1e-6
    iterations = 0
    for iterations in range(1, max_iterations + 1):  # noqa: B007
        JtJ = (J.T @ J).tocsc()
        g = J.T @ res
        diag = JtJ.diagonal()
        while True:
            A = JtJ + sp.diags(lam * np.maximum(diag, 1e-12))
            delta = _solve_spd(A.tocsc(), -g)
            trial_nodes, trial_theta = _apply(model, nodes, theta, delta)
            trial_res, _, _ = problem.evaluate(trial_nodes, trial_theta, want_jac=False)
            trial_cost = 0.5 * float(trial_res @ trial_res)
            if trial_cost <= cost:
                break
            lam *= 10.0
            if lam > 1e8:
                break
        if trial_cost > cost:
            break
        improvement = cost - trial_cost
        nodes, theta = trial_nodes, trial_theta
        lam = max(lam / 10.0, 1e-9)
        res, J, _ = problem.evaluate(nodes, theta, want_jac=True)
        cost = 0.5 * float(res @ res)
        if improvement <= 1e-9 * cost0 or np.max(np.abs(delta[12 * K:])) < 1e-7:
            break

    return BatchResult(
        estimate=ParameterEstimate(theta, _theta_covariance(J, K, model.theta_scale)),
        states=nodes,
        node_times=flight.t[node_idx[:-1]], iterations=iterations, cost_initial=cost0,
        cost_final=cost,
    )
