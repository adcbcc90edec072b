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
    MODE_INFLUENCE,
    MODE_NORMAL,
    MODE_RESIDUALS,
    BlockSystem,
    ThetaBorderedFactor,
    factor,
    inject_kernel,
    shoot_kernel,
    whiten_kernel,
)
from mavsysid.estimation.flight import FlightData, step_process_noise
from mavsysid.estimation.progress import report_progress
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.estimation.robust import inflation_from_scores
from mavsysid.vehicle.linearization import ErrorStateModel
from scipy.optimize import least_squares

from mavsysid.errors import JobFailedError

__all__ = ["INFLATION_DRAWS", "STEP_TOLERANCE", "BatchResult", "LeastSquaresResult",
           "ShootingProblem", "apply_step", "factor_at_optimum", "node_indices",
           "probe_columns", "refine", "shooting_problem", "sigma_inflation",
           "solve_least_squares", "whitening"]

#: The refinement stops where its next Gauss–Newton step would move no estimated
#: quantity by more than this share of its σ.
STEP_TOLERANCE = 0.05

#: Monte-Carlo draws of white residuals the σ inflation is calibrated against
#: (`mavsysid.estimation.robust.inflated_theta_covariance`), and their seed.
INFLATION_DRAWS, INFLATION_SEED = 8, 0


def node_indices(t: np.ndarray, node_interval: float) -> np.ndarray:
    """Sample index of each shooting node, and the sample count last, shape (K+1,).

    ``node_interval`` s between nodes (rounded to whole median sample intervals); 0: a
    node at every sample but the last.
    """
    dt = float(np.median(np.diff(t)))
    step = max(1, round(node_interval / dt))
    return np.append(np.arange(0, len(t) - 1, step), len(t)).astype(np.int64)


def whitening(Q: np.ndarray) -> np.ndarray:
    """W with Wᵀ W = Q⁻¹ for each (12, 12) block of Q (M, 12, 12), robust to a singular Q
    (`mavsysid.estimation.batch.kernels.whiten_kernel`)."""
    W = np.empty_like(Q)
    for k in range(Q.shape[0]):
        whiten_kernel(np.ascontiguousarray(Q[k]), W[k])
    return W


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
             set_w: bool = False, coo: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             system: BlockSystem | None = None,
             probe: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             influence: tuple[np.ndarray, ...] | None = None) -> tuple[np.ndarray, np.ndarray]:
        a = self.arrays
        K, p = self.node_count, self.parameter_count
        res = np.empty(self.residual_count)
        coo = coo if coo is not None else (np.empty(1, np.int64),) * 2 + (np.empty(1),)
        system = system if system is not None else BlockSystem.zeros(1, p)
        probe = probe if probe is not None else (np.empty((1, 0)), np.empty((1, 12, 0)),
                                                 np.empty((p, 0)))
        influence = influence if influence is not None else (
            np.empty((1, 12, 0)), np.empty((p, 0)), np.empty((1, p)), np.empty((0, 1, p)))
        Q_out = np.empty((max(K - 1, 1), 12, 12))
        mass, r, eps, scale = self.model.kernel_args()
        m, _ = shoot_kernel(nodes, theta, a["t"], a["z"], a["n"], a["w"], a["basis"],
                            self.node_idx, mass, r, eps, scale, a["Qc"], self.W,
                            (float(self.sigma[0]), float(self.sigma[1])), mode, want_q, set_w,
                            res, Q_out, (*coo, 12 * K),
                            (system.D, system.U, system.B, system.T, system.g, system.gt),
                            probe, influence)
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
        res, system, _ = self.normal_equations_with_probes(nodes, theta)
        return res, system

    def normal_equations_with_probes(
        self, nodes: np.ndarray, theta: np.ndarray, probes: np.ndarray | None = None,
        whiten: bool = False,
    ) -> tuple[np.ndarray, BlockSystem, tuple[np.ndarray, np.ndarray]]:
        """`normal_equations`, and Jᵀ E for probe columns E in blocks.

        Parameters
        ----------
        nodes, theta
            The point.
        probes : ndarray, shape (M, d), optional
            Probe columns E, one row per residual; none by default.
        whiten : bool
            Set the defects' whitening from this pass's process noise (`interval_noise`)
            before they are formed: the first pass of a problem made by `shooting_problem`
            with ``whitened=False``.

        Returns
        -------
        res : ndarray, shape (M,)
        system : BlockSystem
        probes : tuple of ndarray
            Jᵀ E of the nodes (K, 12, d) and of θ (P, d).
        """
        K, p = self.node_count, self.parameter_count
        E = np.empty((1, 0)) if probes is None else np.ascontiguousarray(probes, dtype=float)
        d = E.shape[1]
        system = BlockSystem.zeros(K, p)
        probe = (E, np.zeros((K, 12, d)), np.zeros((p, d)))
        res, _ = self._run(nodes, theta, MODE_NORMAL, set_w=whiten, system=system, probe=probe)
        w = self.model.theta_scale / self.prior_sigma
        system.T[np.diag_indices(p)] += w * w
        system.gt[:] += w * res[-p:]
        if d:
            probe[2][:] += w[:, None] * E[-p:]
        return res, system, probe[1:]

    def influence(self, nodes: np.ndarray, theta: np.ndarray, probes: np.ndarray,
                  Xn: np.ndarray, Xt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each time sample's share of (J X)ᵀ r, for the data and for white probes.

        Parameters
        ----------
        nodes, theta
            The point (usually the optimum).
        probes : ndarray, shape (M, d)
            White probe columns E, one entry per residual row.
        Xn, Xt : ndarray, shapes (K, 12, P + d) and (P, P + d)
            X = H⁻¹ [E_θ, Jᵀ E] in blocks: the columns of the P quantities, then d more.

        Returns
        -------
        data : ndarray, shape (N, P)
            Σ over each sample's rows of (J X_θ) r (prior rows left out; a defect counts
            with the last sample of its interval).
        white : ndarray, shape (d, N, P)
            The same with r replaced by each probe's E_i − J X_i.
        """
        N, p, d = len(self.flight), self.parameter_count, probes.shape[1]
        data, white = np.zeros((N, p)), np.zeros((d, N, p))
        probe = (np.ascontiguousarray(probes, dtype=float), np.empty((1, 12, 0)),
                 np.empty((p, 0)))
        self._run(nodes, theta, MODE_INFLUENCE, probe=probe,
                  influence=(np.ascontiguousarray(Xn), np.ascontiguousarray(Xt), data, white))
        return data, white

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
            # the sort of a COO conversion (seconds on a 60 s flight at 500 Hz).
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
    node_interval: float = 0.0, wrench: np.ndarray | None = None, whitened: bool = True,
) -> tuple[ShootingProblem, np.ndarray]:
    """The problem `refine` solves, with its defects whitened at the start, and the start nodes.

    Parameters as for `refine`; ``whitened`` False leaves the whitening to the first
    `ShootingProblem.normal_equations_with_probes` (``whiten=True``, at the start nodes and
    θ), which saves a pass over the flight. Returns the problem and the nodes (K, 13) at
    the start.
    """
    node_idx = node_indices(flight.t, node_interval)
    nodes = np.ascontiguousarray(filtered_states[node_idx[:-1]])
    K = nodes.shape[0]
    problem = ShootingProblem(flight, model, node_idx, prior, sigma,
                              np.zeros((max(K - 1, 1), 12, 12)), wrench)
    if whitened:
        problem.W = whitening(problem.interval_noise(nodes, filtered.value))
    return problem, nodes


def _theta_covariance(fac: ThetaBorderedFactor, theta_scale: np.ndarray) -> np.ndarray:
    """θ covariance (P, P), SI: the θ block of (JᵀJ)⁻¹, from its factorisation."""
    cov = fac.theta_inverse() * np.outer(theta_scale, theta_scale)
    return 0.5 * (cov + cov.T)


def probe_columns(problem: ShootingProblem) -> np.ndarray:
    """The seeded white probes of the σ inflation, one row per residual.

    Parameters
    ----------
    problem : ShootingProblem

    Returns
    -------
    ndarray, shape (M, `INFLATION_DRAWS`)
    """
    return np.random.default_rng(INFLATION_SEED).standard_normal(
        (problem.residual_count, INFLATION_DRAWS))


def sigma_inflation(problem: ShootingProblem, nodes: np.ndarray, theta: np.ndarray,
                    fac: ThetaBorderedFactor,
                    probes: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """σ multiplier (P,) ≥ 1 of each quantity at the optimum, from the residuals' HAC.

    `mavsysid.estimation.robust.inflated_theta_covariance` on this problem, from its
    blocks (`ShootingProblem.influence`): rows grouped by sample (a defect with the last
    sample of its interval, the prior rows apart), H⁻¹ b by the optimum's block
    factorisation, the white reference from `probe_columns`. ``probes`` is Jᵀ E of those
    columns at this point, (K, 12, d) and (P, d), if already formed
    (`ShootingProblem.normal_equations_with_probes`); else one more pass forms it.
    """
    E = probe_columns(problem)
    if probes is None:
        probes = problem.normal_equations_with_probes(nodes, theta, E)[2]
    K, p = problem.node_count, problem.parameter_count
    Xn, Xt = fac.solve(np.concatenate([np.zeros((K, 12, p)), probes[0]], axis=2),
                       np.concatenate([np.eye(p), probes[1]], axis=1))
    data, white = problem.influence(nodes, theta, E, Xn, Xt)
    naive = Xt[:, :p]
    G_prior = (problem.model.theta_scale / problem.prior_sigma)[:, None] * naive
    return inflation_from_scores(0.5 * (naive + naive.T), data, white,
                                 G_prior.T @ G_prior)[1]


def _damped_factor(system: BlockSystem, lam: float) -> ThetaBorderedFactor | None:
    """The factor of JᵀJ + λ diag, None if the damped matrix is not positive definite."""
    try:
        return factor(system, lam)
    except np.linalg.LinAlgError:
        return None


def _small_step(fac: ThetaBorderedFactor, step_theta: np.ndarray) -> bool:
    """The θ step (scaled units) moves no quantity by more than `STEP_TOLERANCE` σ."""
    sigma = np.sqrt(np.maximum(np.diag(fac.theta_inverse()), 0.0))
    return bool(np.all(np.abs(step_theta) <= STEP_TOLERANCE * sigma))


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
                                      node_interval, wrench, whitened=False)
    E = probe_columns(problem)
    fit = _levenberg_marquardt(problem, nodes, filtered.value.copy(), E, max_iterations)
    optimum = factor_at_optimum(fit.system, flight.source)
    inflation = sigma_inflation(problem, fit.nodes, fit.theta, optimum, fit.probes)
    return BatchResult(
        estimate=ParameterEstimate(fit.theta, _theta_covariance(optimum, model.theta_scale)
                                   * np.outer(inflation, inflation), filtered.names),
        states=fit.nodes,
        node_times=flight.t[problem.node_idx[:-1]], iterations=fit.iterations,
        cost_initial=fit.cost_initial, cost_final=fit.cost, sigma_inflation=inflation,
    )


@dataclass
class _Optimum:
    """Where `_levenberg_marquardt` stopped: the point, its normal equations and probes,
    the steps taken and the costs."""

    nodes: np.ndarray
    theta: np.ndarray
    system: BlockSystem
    probes: tuple[np.ndarray, np.ndarray]
    iterations: int
    cost_initial: float
    cost: float


def _levenberg_marquardt(problem: ShootingProblem, nodes: np.ndarray, theta: np.ndarray,
                         probes: np.ndarray, max_iterations: int) -> _Optimum:
    """Minimise ½|r|² from (nodes, θ), whitening the defects on the first pass.

    Stops where the next Gauss–Newton step (λ ≤ 1e-4) would move θ by less than
    `STEP_TOLERANCE` σ, or where no damping lowers the cost. Each pass of the normal
    equations also forms Jᵀ E for the σ inflation's probe columns E, so the optimum's is
    at hand.
    """
    model = problem.model
    res, system, jte = problem.normal_equations_with_probes(nodes, theta, probes, whiten=True)
    cost0 = cost = 0.5 * float(res @ res)
    lam = 1e-6
    steps = 0
    for iteration in range(1, max_iterations + 1):
        report_progress("batch refinement", iteration, max_iterations, f"cost {cost:.4g}")
        accepted = converged = False
        while lam <= 1e8 and not (accepted or converged):
            fac = _damped_factor(system, lam)
            if fac is not None:
                step = fac.solve(-system.g, -system.gt)
                converged = lam <= 1e-4 and _small_step(fac, step[1])
                if converged:
                    break
                trial_nodes, trial_theta = apply_step(model, nodes, theta, *step)
                trial_res = problem.residuals(trial_nodes, trial_theta)
                accepted = 0.5 * float(trial_res @ trial_res) <= cost
            if not accepted:
                lam *= 10.0
        if not accepted:
            break
        nodes, theta, steps = trial_nodes, trial_theta, steps + 1
        lam = max(lam / 10.0, 1e-9)
        res, system, jte = problem.normal_equations_with_probes(nodes, theta, probes)
        cost = 0.5 * float(res @ res)
    return _Optimum(nodes, theta, system, jte, steps, cost0, cost)


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
