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
drift. Levenberg–Marquardt with the Jacobian built from the shared linearisation
(transition matrices along each interval). JᵀJ is block tridiagonal with a θ border; the
kernel accumulates its blocks directly and a block Cholesky solves it without fill
(`mavsysid.estimation.block_solve`); the θ covariance is the θ block of (JᵀJ)⁻¹ at the
optimum, the inverse Schur complement of that factorisation. (A general sparse J with
SuperLU, and `scipy.optimize.least_squares` on the same problem, were measured slower:
`bench/estimate_speed.py`, `mavsysid.estimation.batch_scipy`.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.batch_problem import (
    ShootingProblem,
    apply_step,
    node_indices,
    whitening,
)
from mavsysid.estimation.block_solve import BlockSystem, ThetaBorderedFactor, factor
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.progress import report_progress
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.estimation.robust_covariance import inflated_theta_covariance
from mavsysid.vehicle.linearization import ErrorStateModel

from mavsysid.errors import JobFailedError

__all__ = ["BatchResult", "factor_at_optimum", "refine", "shooting_problem", "sigma_inflation"]


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
    sigma_inflation : ndarray, shape (6,), optional
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
    """θ covariance (6, 6), SI: the θ block of (JᵀJ)⁻¹, from its factorisation."""
    cov = fac.theta_inverse() * np.outer(theta_scale, theta_scale)
    return 0.5 * (cov + cov.T)


def sigma_inflation(problem: ShootingProblem, nodes: np.ndarray, theta: np.ndarray,
                    fac: ThetaBorderedFactor) -> np.ndarray:
    """σ multiplier (6,) ≥ 1 of each parameter at the optimum, from the residuals' HAC.

    `mavsysid.estimation.robust_covariance.inflated_theta_covariance` on this problem:
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

    rows = np.full(len(problem.flight), 6)
    rows[problem.node_idx[1:-1] - 1] += 12
    sample = np.append(np.repeat(np.arange(rows.size), rows), np.full(6, -1))
    return inflated_theta_covariance(J, res, solve, 12 * K + np.arange(6), sample,
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
        in the model's terms (`mavsysid.estimation.effect_channels.ModelTerms`).
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
                                   * np.outer(inflation, inflation)),
        states=nodes,
        node_times=flight.t[problem.node_idx[:-1]], iterations=iterations, cost_initial=cost0,
        cost_final=cost, sigma_inflation=inflation,
    )
