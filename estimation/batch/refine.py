"""Batch maximum-a-posteriori refinement: states and θ jointly over the whole flight.

In the spirit of Burri et al.'s maximum-likelihood identification, and because the paper
found its EKF overconfident on real flights, the filter's estimate is refined by a batch
MAP over states and θ jointly, posed as multiple shooting: nodes at every sample by
default (or every ``node_interval`` seconds); the unknowns are the model state at each
node (as a 12-D error of the filtered state) and the P estimated quantities (as scaled
errors). The cost is

    Σ_samples |pose residual / σ|²  +  Σ_nodes |W_k (x_{k+1} ⊟ Φ(x_k, θ))|²  +  |θ prior|²,

where Φ integrates the model (RK4, logged rotor speeds) from one node to the next and W_k
whitens the defect with the process noise accumulated over the interval (at the level the
caller chose, e.g. fitted by `mavsysid.estimation.filter.likelihood`). The defects let
the states follow the data, so a long flight does not drift off. `ShootingProblem` holds
the flight in the kernels' arrays and evaluates the residuals with their Jacobian, as a
sparse matrix or directly as the blocks of JᵀJ and Jᵀr that `refine` solves
(`mavsysid.estimation.batch.kernels`); `solve_least_squares` solves the same problem with
`scipy.optimize.least_squares`, the reference the refinement is measured against. θ's
covariance is inflated by the residuals' HAC against a correct model's
(`mavsysid.estimation.robust.inflated_theta_covariance`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from mavsysid.estimation.batch.kernels import (
    MODE_COO,
    MODE_NORMAL,
    MODE_RESIDUALS,
    BlockSystem,
    ThetaBorderedFactor,
    factor,
    inject_kernel,
    shoot_kernel,
)
from mavsysid.estimation.flight import FlightData, step_process_noise
from mavsysid.estimation.progress import report_progress
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.estimation.robust import inflated_theta_covariance
from mavsysid.vehicle.linearization import ErrorStateModel
from scipy.optimize import least_squares

from mavsysid.errors import JobFailedError

__all__ = ["BatchResult", "LeastSquaresResult", "ShootingProblem", "apply_step",
           "factor_at_optimum", "node_indices", "refine", "shooting_problem", "sigma_inflation",
           "solve_least_squares", "whitening"]


def node_indices(t: np.ndarray, node_interval: float) -> np.ndarray:
    """Sample index of each shooting node, and the sample count last, shape (K+1,).

    ``node_interval`` s between nodes (rounded to whole median sample intervals); 0: a
    node at every sample but the last.
    """
    dt = float(np.median(np.diff(t)))
    step = max(1, round(node_interval / dt))
    return np.append(np.arange(0, len(t) - 1, step), len(t)).astype(np.int64)


def whitening(Q: np.ndarray) -> np.ndarray:
    """W with Wᵀ W = Q⁻¹ for each (12, 12) block of Q (M, 12, 12), robust to a singular Q."""
    tr = np.trace(Q, axis1=1, axis2=2)
    q = 0.5 * (Q + np.swapaxes(Q, 1, 2)) + np.eye(12) * (1e-12 + 1e-9 * tr / 12)[:, None, None]
    return np.linalg.inv(np.linalg.cholesky(q))


def apply_step(model: ErrorStateModel, nodes: np.ndarray, theta: np.ndarray,
               step_nodes: np.ndarray, step_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes ⊞ their steps (K, 12) and θ + scale × its step (P,), SI."""
    new_nodes = np.empty_like(nodes)
    for k in range(nodes.shape[0]):
        inject_kernel(nodes[k], step_nodes[k], new_nodes[k])
    return new_nodes, theta + model.theta_scale * step_theta


@dataclass
class ShootingProblem:
    """The shooting problem of one flight segment.

    Attributes
    ----------
    flight : FlightData
        In the model's terms.
    model : ErrorStateModel
    node_idx : ndarray, shape (K+1,)
        From `node_indices`.
    prior : ParameterEstimate
    sigma : tuple of 2 float
        Position σ (m) and attitude σ (rad) of the measurements.
    W : ndarray, shape (max(K-1, 1), 12, 12)
        Whitening of each defect (set from `interval_noise`).
    wrench : ndarray, shape (N, 6), optional
        Known effects' body force (N) and torque (N·m).
    """

    flight: FlightData
    model: ErrorStateModel
    node_idx: np.ndarray
    prior: ParameterEstimate
    sigma: tuple[float, float]
    W: np.ndarray
    wrench: np.ndarray | None = None
    arrays: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        fl = self.flight
        t = np.ascontiguousarray(fl.t, dtype=float)
        n = np.ascontiguousarray(fl.rotor_speeds, dtype=float)
        _, r, eps, _ = self.model.kernel_args()
        self.arrays = {
            "t": t, "z": np.ascontiguousarray(np.hstack([fl.position, fl.quaternion])), "n": n,
            "w": (np.zeros((len(fl), 6)) if self.wrench is None
                  else np.ascontiguousarray(self.wrench, dtype=float)),
            # Each step's process noise, with the slow inputs' interpolation error.
            "Qc": step_process_noise(self.model.process_noise_density(), t, n, fl.inputs,
                                     self.prior.value, r, eps),
            # The nuisance quantities' wrench per unit value, on the pose's states.
            "basis": np.ascontiguousarray(self.model.extra_basis(
                fl.pose_states(), n, self.prior.value, t - t[0])),
        }

    @property
    def parameter_count(self) -> int:
        """P: θ and the nuisance quantities."""
        return self.model.parameter_count

    @property
    def node_count(self) -> int:
        """K."""
        return len(self.node_idx) - 1

    @property
    def residual_count(self) -> int:
        """Rows of the residual vector: 6 per sample, 12 per defect, P for the prior."""
        return 6 * len(self.flight) + 12 * (self.node_count - 1) + self.parameter_count

    def _run(self, nodes: np.ndarray, theta: np.ndarray, mode: int, want_q: bool = False,
             coo: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             system: BlockSystem | None = None) -> tuple[np.ndarray, np.ndarray]:
        a = self.arrays
        K = self.node_count
        res = np.empty(self.residual_count)
        rows, cols, vals = coo if coo is not None else (np.empty(1, np.int64),) * 2 + (
            np.empty(1),)
        system = system if system is not None else BlockSystem.zeros(1, self.parameter_count)
        Q_out = np.empty((max(K - 1, 1), 12, 12))
        mass, r, eps, scale = self.model.kernel_args()
        m, _ = shoot_kernel(nodes, theta, a["t"], a["z"], a["n"], a["w"], a["basis"],
                            self.node_idx, mass, r, eps, scale, a["Qc"], self.W, self.sigma[0],
                            self.sigma[1], mode, want_q, res, rows, cols, vals, Q_out, system.D,
                            system.U, system.B, system.T, system.g, system.gt)
        res[m:] = (theta - self.prior.value) / self.prior_sigma
        return res, Q_out

    @property
    def prior_sigma(self) -> np.ndarray:
        """σ of the θ prior, SI (P,)."""
        return np.sqrt(np.diag(self.prior.covariance))

    def interval_noise(self, nodes: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Process noise accumulated over each node interval, (max(K-1, 1), 12, 12)."""
        return self._run(nodes, theta, MODE_RESIDUALS, want_q=True)[1]

    def residuals(self, nodes: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """The whitened residual vector r."""
        return self._run(nodes, theta, MODE_RESIDUALS)[0]

    def normal_equations(self, nodes: np.ndarray, theta: np.ndarray
                         ) -> tuple[np.ndarray, BlockSystem]:
        """r, and JᵀJ with Jᵀr in blocks (θ in its scaled units)."""
        p = self.parameter_count
        system = BlockSystem.zeros(self.node_count, p)
        res, _ = self._run(nodes, theta, MODE_NORMAL, system=system)
        w = self.model.theta_scale / self.prior_sigma
        system.T[np.diag_indices(p)] += w * w
        system.gt[:] += w * res[-p:]
        return res, system

    def jacobian(self, nodes: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """r and J as a sparse matrix (columns: 12 per node, then the P scaled quantities)."""
        K, p = self.node_count, self.parameter_count
        n_meas = len(self.flight)
        m = self.residual_count - p
        nnz = 6 * (12 + p) * n_meas + 12 * (24 + p) * (K - 1)
        coo = (np.empty(nnz, np.int64), np.empty(nnz, np.int64), np.empty(nnz))
        res, _ = self._run(nodes, theta, MODE_COO, coo=coo)
        rows = np.concatenate([coo[0], m + np.arange(p)])
        cols = np.concatenate([coo[1], 12 * K + np.arange(p)])
        vals = np.concatenate([coo[2], self.model.theta_scale / self.prior_sigma])
        shape = (m + p, 12 * K + p)
        if np.all(rows[1:] >= rows[:-1]):
            # The kernel writes row by row with no repeated column: CSR directly, without
            # the sort of a COO conversion (2 s of a 60 s, 500 Hz estimate).
            indptr = np.searchsorted(rows, np.arange(shape[0] + 1))
            return res, sp.csr_matrix((vals, cols, indptr), shape=shape)
        return res, sp.csr_matrix((vals, (rows, cols)), shape=shape)


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
    sigma_inflation : ndarray, shape (P,), optional
        How much each σ was widened (≥ 1) for residuals correlated or larger than the
        model assumes (`sigma_inflation`).
    """

    estimate: ParameterEstimate
    states: np.ndarray
    node_times: np.ndarray
    iterations: int
    cost_initial: float
    cost_final: float
    sigma_inflation: np.ndarray | None = None


def shooting_problem(
    flight: FlightData, filtered_states: np.ndarray, filtered: ParameterEstimate,
    model: ErrorStateModel, prior: ParameterEstimate, sigma: tuple[float, float],
    node_interval: float = 0.0, wrench: np.ndarray | None = None,
) -> tuple[ShootingProblem, np.ndarray]:
    """The problem `refine` solves, with its defects whitened at the start, and the start nodes.

    Parameters as for `refine`. Returns the problem and the nodes (K, 13) at the start.
    """
    node_idx = node_indices(flight.t, node_interval)
    nodes = np.ascontiguousarray(filtered_states[node_idx[:-1]])
    K = nodes.shape[0]
    problem = ShootingProblem(flight, model, node_idx, prior, sigma,
                              np.zeros((max(K - 1, 1), 12, 12)), wrench)
    problem.W = whitening(problem.interval_noise(nodes, filtered.value))
    return problem, nodes


def _theta_covariance(fac: ThetaBorderedFactor, theta_scale: np.ndarray) -> np.ndarray:
    """θ covariance (P, P), SI: the θ block of (JᵀJ)⁻¹, from its factorisation."""
    cov = fac.theta_inverse() * np.outer(theta_scale, theta_scale)
    return 0.5 * (cov + cov.T)


def sigma_inflation(problem: ShootingProblem, nodes: np.ndarray, theta: np.ndarray,
                    fac: ThetaBorderedFactor) -> np.ndarray:
    """σ multiplier (P,) ≥ 1 of each quantity at the optimum, from the residuals' HAC.

    `mavsysid.estimation.robust.inflated_theta_covariance` on this problem:
    rows grouped by sample (a defect with the last sample of its interval, the prior
    rows apart), H⁻¹ b by the optimum's block factorisation.
    """
    res, J = problem.jacobian(nodes, theta)
    K = problem.node_count

    def solve(b: np.ndarray) -> np.ndarray:
        out = np.empty_like(b)
        for i in range(b.shape[1]):
            x, xt = fac.solve(np.ascontiguousarray(b[:12 * K, i]).reshape(K, 12),
                              np.ascontiguousarray(b[12 * K:, i]))
            out[:12 * K, i], out[12 * K:, i] = x.ravel(), xt
        return out

    p = problem.parameter_count
    rows = np.full(len(problem.flight), 6)
    rows[problem.node_idx[1:-1] - 1] += 12
    sample = np.append(np.repeat(np.arange(rows.size), rows), np.full(p, -1))
    return inflated_theta_covariance(J, res, solve, 12 * K + np.arange(p), sample,
                                     rows.size)[1]


def _damped_step(system: BlockSystem, lam: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The LM step −(JᵀJ + λ diag)⁻¹ Jᵀr, None if the damped matrix is not positive definite."""
    try:
        return factor(system, lam).solve(-system.g, -system.gt)
    except np.linalg.LinAlgError:
        return None


def factor_at_optimum(system: BlockSystem, source: str) -> ThetaBorderedFactor:
    """The factor of JᵀJ at the optimum, for the covariance and its inflation.

    The prior rows keep JᵀJ positive definite in exact arithmetic, but the defect weights
    span many decades and a node block can lose definiteness to rounding; a relative
    damping of 1e-12 or 1e-10 changes no σ in its fourth digit. Past that the flight leaves
    the states or θ undetermined to working precision, and the estimate is refused.
    """
    for lam in (0.0, 1e-12, 1e-10):
        try:
            return factor(system, lam)
        except np.linalg.LinAlgError:
            continue
    raise JobFailedError(
        f"{source}: estimate refused: the flight does not determine θ (the batch normal "
        "matrix is singular at its optimum); check the vehicle file, or fly a more "
        "exciting trajectory")


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
        in the model's terms (`mavsysid.estimation.filter.likelihood.ModelTerms`).
    """
    problem, nodes = shooting_problem(flight, filtered_states, filtered, model, prior, sigma,
                                      node_interval, wrench)
    theta = filtered.value.copy()
    res, system = problem.normal_equations(nodes, theta)
    cost0 = cost = 0.5 * float(res @ res)
    lam = 1e-6
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        report_progress("batch refinement", iterations, max_iterations, f"cost {cost:.4g}")
        while True:
            step = _damped_step(system, lam)
            trial_cost = np.inf
            if step is not None:
                trial_nodes, trial_theta = apply_step(model, nodes, theta, *step)
                trial_res = problem.residuals(trial_nodes, trial_theta)
                trial_cost = 0.5 * float(trial_res @ trial_res)
            if trial_cost <= cost:
                break
            lam *= 10.0
            if lam > 1e8:
                break
        if not trial_cost <= cost:
            break
        improvement = cost - trial_cost
        nodes, theta = trial_nodes, trial_theta
        lam = max(lam / 10.0, 1e-9)
        res, system = problem.normal_equations(nodes, theta)
        cost = 0.5 * float(res @ res)
        if improvement <= 1e-9 * cost0 or np.max(np.abs(step[1])) < 1e-7:
            break

    optimum = factor_at_optimum(system, flight.source)
    inflation = sigma_inflation(problem, nodes, theta, optimum)
    return BatchResult(
        estimate=ParameterEstimate(theta, _theta_covariance(optimum, model.theta_scale)
                                   * np.outer(inflation, inflation), filtered.names),
        states=nodes,
        node_times=flight.t[problem.node_idx[:-1]], iterations=iterations, cost_initial=cost0,
        cost_final=cost, sigma_inflation=inflation,
    )


@dataclass(frozen=True)
class LeastSquaresResult:
    """What `solve_least_squares` found.

    Attributes
    ----------
    theta : ndarray, shape (P,)
        θ (and the nuisance quantities) at the end, SI.
    nodes : ndarray, shape (K, 13)
    cost : float
        ½ Σ r² at the end.
    evaluations : int
        Residual evaluations.
    status : int
        ``least_squares``' status (> 0: converged by a tolerance).
    """

    theta: np.ndarray
    nodes: np.ndarray
    cost: float
    evaluations: int
    status: int


def solve_least_squares(problem: ShootingProblem, nodes: np.ndarray, theta: np.ndarray,
                        max_evaluations: int = 30, tol: float = 1e-10) -> LeastSquaresResult:
    """Minimise the shooting problem's ½|r|² with `scipy.optimize.least_squares`.

    Parameters
    ----------
    problem : ShootingProblem
        With its defect whitening set (`mavsysid.estimation.batch.refine.shooting_problem`).
    nodes : ndarray, shape (K, 13)
        The start.
    theta : ndarray, shape (P,)
        The start, SI.
    max_evaluations : int
        ``max_nfev``.
    tol : float
        ``ftol``, ``xtol`` and ``gtol``.
    """
    K = nodes.shape[0]
    model = problem.model

    def unpack(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return apply_step(model, nodes, theta, u[:12 * K].reshape(K, 12), u[12 * K:])

    def fun(u: np.ndarray) -> np.ndarray:
        return problem.residuals(*unpack(u))

    def jac(u: np.ndarray) -> sp.csr_matrix:
        return problem.jacobian(*unpack(u))[1]

    sol = least_squares(fun, np.zeros(12 * K + problem.parameter_count), jac=jac,
                        method="trf", tr_solver="lsmr", x_scale="jac",
                        max_nfev=max_evaluations, ftol=tol, xtol=tol, gtol=tol)
    end_nodes, end_theta = unpack(sol.x)
    return LeastSquaresResult(end_theta, end_nodes, float(sol.cost), int(sol.nfev),
                              int(sol.status))
