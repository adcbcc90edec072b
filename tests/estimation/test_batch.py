"""The batch refinement: its block solver, its normal equations, and what the LM reaches."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from mavsysid.estimation.batch.kernels import BlockSystem, factor
from mavsysid.estimation.batch.refine import (
    factor_at_optimum,
    node_indices,
    probe_columns,
    refine,
    shooting_problem,
    solve_least_squares,
)
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    flight_initial_state_sigma,
)
from mavsysid.estimation.filter.likelihood import scaled_noise
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import ParameterEstimate, prior_from_config
from mavsysid.estimation.robust import influence_by_sample
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import JobFailedError


def random_system(K: int, seed: int) -> BlockSystem:
    """JᵀJ of a random Jacobian with the refinement's sparsity, scales spread over 1e±4."""
    rng = np.random.default_rng(seed)
    n = 12 * K + 6
    J = np.zeros((30 * K, n))
    for k in range(K):
        cols = list(range(12 * k, 12 * k + (24 if k < K - 1 else 12))) + list(range(12 * K, n))
        J[np.ix_(range(30 * k, 30 * k + 30), cols)] = rng.normal(size=(30, len(cols)))
    J *= 10.0 ** rng.uniform(-4, 4, n)
    A, b = J.T @ J, rng.normal(size=n)
    s = BlockSystem.zeros(K)
    for k in range(K):
        blk = slice(12 * k, 12 * k + 12)
        s.D[k], s.B[k], s.g[k] = A[blk, blk], A[blk, 12 * K:], b[blk]
        if k < K - 1:
            s.U[k] = A[blk, 12 * k + 12:12 * k + 24]
    s.T[:], s.gt[:] = A[12 * K:, 12 * K:], b[12 * K:]
    return s


@pytest.mark.parametrize(("K", "lam"), [(1, 0.0), (7, 0.0), (7, 1e-3)])
def test_block_solver_matches_a_dense_solve(K, lam):
    """Solution and θ block of the inverse equal numpy's on the dense (damped) matrix."""
    s = random_system(K, seed=K)
    A = s.dense()
    A = A + lam * np.diag(np.diag(A))
    b = np.concatenate([s.g.ravel(), s.gt])
    xn, xt = factor(s, lam).solve(s.g, s.gt)
    expected = np.linalg.solve(A, b)
    scale = np.sqrt(np.diag(A))  # compare in the Jacobi-scaled units the solver works in
    np.testing.assert_allclose(np.concatenate([xn.ravel(), xt]) * scale, expected * scale,
                               rtol=1e-6, atol=1e-8 * np.max(np.abs(expected * scale)))
    inv = np.linalg.inv(A)[12 * K:, 12 * K:]
    np.testing.assert_allclose(factor(s, lam).theta_inverse(), inv, rtol=1e-6)


def test_block_solver_refuses_an_indefinite_matrix():
    """A matrix that is not positive definite raises LinAlgError (the LM then damps more)."""
    s = random_system(3, seed=1)
    s.D[1][np.diag_indices(12)] *= -1.0
    with pytest.raises(np.linalg.LinAlgError):
        factor(s)


def test_an_indefinite_optimum_is_refused_in_one_line():
    """Where no small damping makes JᵀJ definite, the estimate is refused naming the log."""
    s = random_system(3, seed=1)
    assert np.allclose(factor_at_optimum(s, "x.tlog").theta_inverse(), factor(s).theta_inverse())
    s.D[1][np.diag_indices(12)] *= -1.0
    with pytest.raises(JobFailedError, match=r"^x\.tlog: estimate refused: .*singular"):
        factor_at_optimum(s, "x.tlog")


def test_node_indices_cover_the_flight():
    """Nodes start at sample 0, are evenly spaced by the interval, and end with N."""
    t = np.arange(1000) * 0.002
    np.testing.assert_array_equal(node_indices(t, 0.0), np.append(np.arange(999), 1000))
    idx = node_indices(t, 0.01)
    assert idx[0] == 0 and idx[-1] == 1000
    assert set(np.diff(idx[:-1])) == {5}


@pytest.fixture(scope="module")
def start(tmp_path_factory):
    """A seeded 8 s flight at 50 Hz, a prior 20 % off, and the filter's run over it."""
    truth = load_vehicle("firefly")
    directory = tmp_path_factory.mktemp("batch") / "flight"
    Simulator(truth, settings=SimulationSettings(seed=3, log_rate=50.0)).run(
        excitation_trajectory(ExcitationSpec(duration=8.0)), directory)
    log = read_pose_log(directory / "pose.csv", truth.rotor_count)
    flight = FlightData(log.t, log.position, log.quaternion, log.rotor_speeds,
                        str(directory / "pose.csv"),
                        truth=read_meta(directory / "meta.json")["truth"])
    config = truth.with_parameters(truth.theta * np.array([1.2, 0.8, 1.2, 0.8, 1.2, 0.8]))
    prior = prior_from_config(config, EstimatorSettings())
    sigma = (config.noise.position_sigma, config.noise.attitude_sigma)
    ekf = ParameterEKF(scaled_noise(config, 0.05), prior, sigma)
    run = ekf.run(flight, flight_initial_state_sigma(flight, sigma), None)
    args = (flight, run.states, run.estimate, ekf.model, prior, sigma)
    return SimpleNamespace(args=args, truth=truth.theta, run=run)


def test_normal_equations_equal_the_sparse_jacobian_products(start):
    """The kernel's blocks of JᵀJ and Jᵀr equal the products of the sparse J (the old path)."""
    problem, nodes = shooting_problem(*start.args)
    theta = start.run.estimate.value
    res, J = problem.jacobian(nodes, theta)
    res2, system = problem.normal_equations(nodes, theta)
    np.testing.assert_allclose(res2, res, rtol=1e-12)
    JtJ = (J.T @ J).toarray()
    scale = np.sqrt(np.diag(JtJ))
    np.testing.assert_allclose(system.dense() / np.outer(scale, scale),
                               JtJ / np.outer(scale, scale), atol=1e-9)
    np.testing.assert_allclose(np.concatenate([system.g.ravel(), system.gt]), J.T @ res,
                               rtol=1e-9, atol=1e-9 * np.max(np.abs(J.T @ res)))


def test_refinement_lowers_the_cost_and_reports_a_valid_covariance(start):
    """Cost never rises; θ covariance symmetric positive definite."""
    batch = refine(*start.args)
    assert batch.cost_final < batch.cost_initial
    cov = batch.estimate.covariance
    np.testing.assert_array_equal(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0.0)


def test_refinement_from_a_worse_start_reaches_the_same_optimum(start):
    """θ started 2 % off the filter's: a higher starting cost, the same θ (to 0.05 σ)."""
    batch = refine(*start.args)
    flight, states, filtered, model, prior, sigma = start.args
    worse = ParameterEstimate(filtered.value * np.array([1.02, 0.98, 1.02, 0.98, 1.02, 0.98]),
                              filtered.covariance)
    other = refine(flight, states, worse, model, prior, sigma)
    assert other.cost_initial > batch.cost_initial
    z = np.abs(other.estimate.value - batch.estimate.value) / batch.estimate.sigma
    assert np.all(z < 0.05), z


def test_covariance_is_the_theta_block_of_the_inverse_hessian(start):
    """At the optimum, the θ covariance is the θ block of (JᵀJ)⁻¹ from the sparse J, times the
    σ inflation (`mavsysid.estimation.robust`) on both sides."""
    batch = refine(*start.args)
    problem, _ = shooting_problem(*start.args)
    _, J = problem.jacobian(batch.states, batch.estimate.value)
    K = batch.states.shape[0]
    A = (J.T @ J).toarray()
    d = 1.0 / np.sqrt(np.diag(A))  # Jacobi scaling: the defect weights are huge
    inv = (np.linalg.inv(A * np.outer(d, d)) * np.outer(d, d))[12 * K:, 12 * K:]
    scale = problem.model.theta_scale
    naive = batch.estimate.covariance / np.outer(batch.sigma_inflation, batch.sigma_inflation)
    np.testing.assert_allclose(naive, inv * np.outer(scale, scale), rtol=1e-5)


@pytest.mark.slow
def test_least_squares_ends_no_lower_than_the_refinement(start):
    """scipy's least_squares (trf + LSMR) on the same problem reaches no lower a cost.

    Measured (bench/estimate_speed.py): it does not converge in its evaluation budget on
    this problem, which is why the refinement keeps its own LM and block solver.
    """
    batch = refine(*start.args)
    problem, nodes = shooting_problem(*start.args)
    sol = solve_least_squares(problem, nodes, start.run.estimate.value, max_evaluations=15)
    assert sol.cost < batch.cost_initial
    assert sol.cost >= batch.cost_final * (1.0 - 1e-9)


def test_influence_from_the_blocks_equals_the_sparse_jacobian_products(start):
    """Jᵀ E of the normal-equations pass and each sample's influence (data and white
    probes) equal the products of the sparse J, which the σ inflation once formed."""
    batch = refine(*start.args)
    problem, _ = shooting_problem(*start.args)
    nodes, theta = batch.states, batch.estimate.value
    E = probe_columns(problem)
    res, system, (Etn, Ett) = problem.normal_equations_with_probes(nodes, theta, E)
    res_sparse, J = problem.jacobian(nodes, theta)
    np.testing.assert_allclose(res, res_sparse, rtol=1e-12)
    JtE = J.T @ E
    K, p = problem.node_count, problem.parameter_count
    got = np.concatenate([Etn.reshape(12 * K, -1), Ett])
    np.testing.assert_allclose(got, JtE, rtol=1e-9, atol=1e-9 * np.max(np.abs(JtE)))
    fac = factor_at_optimum(system, "x")
    Xn, Xt = fac.solve(np.concatenate([np.zeros((K, 12, p)), Etn], axis=2),
                       np.concatenate([np.eye(p), Ett], axis=1))
    data, white = problem.influence(nodes, theta, E, Xn, Xt)
    X = np.concatenate([Xn.reshape(12 * K, -1), Xt])
    rows = np.full(len(problem.flight), 6)
    rows[problem.node_idx[1:-1] - 1] += 12
    sample = np.append(np.repeat(np.arange(rows.size), rows), np.full(p, -1))
    expected = influence_by_sample(J, res, X[:, :p], sample, rows.size)
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(data, expected, atol=1e-9 * scale)
    for i in range(E.shape[1]):
        probe = E[:, i] - J @ X[:, p + i]
        expected = influence_by_sample(J, probe, X[:, :p], sample, rows.size)
        np.testing.assert_allclose(white[i], expected, atol=1e-9 * np.max(np.abs(expected)))
