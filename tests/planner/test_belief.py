"""Tests of belief propagation: the star-product transfer against the step-by-step EKF."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.planner.belief import (
    apply_transfer,
    edge_samples,
    edge_transfer,
    identity_transfer,
    propagate_final,
    propagate_steps,
    riccati_final,
    segments_samples,
    star,
    steps_transfer,
)
from mavsysid.planner.segments import VertexState, connect_fixed, to_piecewise
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.linearization import E_THETA, ErrorStateModel, initial_state_sigma
from mavsysid.vehicle.trajectory import PiecewisePolynomial, hermite_coefficients


def _random_segments(count: int, seed: int) -> list[PiecewisePolynomial]:
    """Chained Hermite segments through random moderate states (a flyable zig-zag)."""
    rng = np.random.default_rng(seed)
    pos = np.zeros((count + 1, 5, 3))
    pos[:, 0] = rng.uniform([-1.5, -1.5, 1.0], [1.5, 1.5, 2.0], (count + 1, 3))
    pos[1:, 1:3] = rng.normal(0.0, [[1.0], [2.0]], (count, 2, 3))
    yaw = np.zeros((count + 1, 3))
    yaw[:, 0] = rng.uniform(-1.0, 1.0, count + 1)
    yaw[1:, 1] = rng.normal(0.0, 0.3, count)
    durations = rng.uniform(0.8, 2.0, count)
    return [PiecewisePolynomial(
        durations[i:i + 1],
        hermite_coefficients(pos[i], pos[i + 1], durations[i])[None],
        hermite_coefficients(yaw[i], yaw[i + 1], durations[i])[None]) for i in range(count)]


def _start_covariance(cfg, rate=100.0):
    s = initial_state_sigma(cfg.noise.position_sigma, cfg.noise.attitude_sigma, 1.0 / rate)
    sigma = np.diag(np.concatenate([np.full(3, v**2) for v in s] + [np.full(6, 0.25)]))
    return sigma


def _theta_error(a: np.ndarray, b: np.ndarray) -> float:
    """Relative error on the θ block, in scaled (relative-to-θ) coordinates."""
    return float(np.linalg.norm(a[E_THETA, E_THETA] - b[E_THETA, E_THETA])
                 / np.linalg.norm(b[E_THETA, E_THETA]))


@pytest.mark.parametrize("name", ["firefly", "micro_quad"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_step_transfer_equals_step_by_step_ekf(name, seed):
    """Σ ⋆ S_edge equals the step-by-step EKF covariance to < 1e-9 relative on θ (scaled)."""
    cfg = load_vehicle(name)
    model = ErrorStateModel.for_vehicle(cfg)
    sigma0 = _start_covariance(cfg)
    for segment in _random_segments(3, seed):
        states, n, dt = edge_samples(segment, cfg, cfg.theta, 100.0)
        reference = propagate_steps(model, sigma0, states, n, cfg.theta, dt)[-1]
        transferred = apply_transfer(sigma0, edge_transfer(model, states, n, cfg.theta, dt))
        assert _theta_error(transferred, reference) < 1e-9


def test_chains_of_five_edges_compose():
    """Five edges: composed transfer, edge-by-edge transfers and the step-by-step EKF agree."""
    cfg = load_vehicle("firefly")
    model = ErrorStateModel.for_vehicle(cfg)
    sigma0 = _start_covariance(cfg)
    composed, by_edge, reference = identity_transfer(), sigma0, sigma0
    for segment in _random_segments(5, 7):
        states, n, dt = edge_samples(segment, cfg, cfg.theta, 100.0)
        transfer = edge_transfer(model, states, n, cfg.theta, dt)
        composed = star(composed, transfer)
        by_edge = apply_transfer(by_edge, transfer)
        reference = propagate_steps(model, reference, states, n, cfg.theta, dt)[-1]
    assert _theta_error(by_edge, reference) < 1e-9
    assert _theta_error(apply_transfer(sigma0, composed), reference) < 1e-9


def test_a_shared_vertex_is_measured_once():
    """Two chained edges take exactly as many measurements as one edge over both spans."""
    cfg = load_vehicle("firefly")
    model = ErrorStateModel.for_vehicle(cfg)
    sigma0 = _start_covariance(cfg)
    seg = _random_segments(1, 3)[0]
    states, n, dt = edge_samples(seg, cfg, cfg.theta, 100.0)
    whole = propagate_steps(model, sigma0, states, n, cfg.theta, dt)[-1]
    half = len(states) // 2
    first = edge_transfer(model, states[:half + 1], n[:half + 1], cfg.theta, dt)
    second = edge_transfer(model, states[half:], n[half:], cfg.theta, dt)
    chained = apply_transfer(apply_transfer(sigma0, first), second)
    assert _theta_error(chained, whole) < 1e-9
    # Counting the shared sample twice would be visibly different.
    twice = apply_transfer(apply_transfer(sigma0, first), edge_transfer(
        model, states[half - 1:], n[half - 1:], cfg.theta, dt))
    assert _theta_error(twice, whole) > 1e-6


def test_identity_transfer_leaves_a_belief_unchanged():
    """The empty edge maps Σ to Σ."""
    cfg = load_vehicle("quad_x")
    sigma0 = _start_covariance(cfg)
    np.testing.assert_allclose(apply_transfer(sigma0, identity_transfer()), sigma0)


@pytest.mark.parametrize("seed", [0, 4])
def test_compiled_recursion_and_steps_transfer_equal_the_step_by_step_ekf(seed):
    """`propagate_final` and the transfer built from the same F and Q match `propagate_steps`."""
    cfg = load_vehicle("firefly")
    model = ErrorStateModel.for_vehicle(cfg)
    sigma0 = _start_covariance(cfg)
    for segment in _random_segments(3, seed):
        states, n, dt = edge_samples(segment, cfg, cfg.theta, 25.0)
        reference = propagate_steps(model, sigma0, states, n, cfg.theta, dt)[-1]
        assert _theta_error(propagate_final(model, sigma0, states, n, cfg.theta, dt),
                            reference) < 1e-9
        F, Q = model.discrete(states[:-1], n[:-1], cfg.theta, dt)
        assert _theta_error(riccati_final(model, sigma0, F, Q), reference) < 1e-9
        assert _theta_error(apply_transfer(sigma0, steps_transfer(model, F, Q)), reference) < 1e-9


def test_batched_samples_equal_per_segment_samples():
    """One flatness call over several segments gives each segment's own samples."""
    cfg = load_vehicle("firefly")
    start = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    middle = VertexState(np.array([[1.0, 0.5, 1.8], [0.5, 1.5, 0.0], [0.0, -1.0, 0.5],
                                   [1.0, 0.0, 0.0], [0.0, 3.0, 1.0]]), np.array([1.0, 0.2, -1.0]))
    segments = [connect_fixed(start, middle, 1.7), connect_fixed(middle, start, 2.23)]
    batched = segments_samples(segments, cfg, cfg.theta, 25.0)
    assert len(batched) == 2
    for segment, (states, n, dt) in zip(segments, batched, strict=True):
        s0, n0, dt0 = edge_samples(to_piecewise([segment]), cfg, cfg.theta, 25.0)
        assert states.shape == s0.shape and dt == dt0
        np.testing.assert_allclose(states, s0, atol=1e-9)
        np.testing.assert_allclose(n, n0, rtol=1e-9)
