"""Tests of the shared covariance step and pose measurement (`mavsysid.vehicle.covariance`).

The central check: on one flown trajectory, linearised at the same θ with the same step,
the planner's predicted covariance (step by step and by its star-product transfer) is the
parameter EKF's covariance.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.planner.belief import apply_transfer, edge_samples, edge_transfer, propagate_steps
from mavsysid.vehicle.covariance import (
    MEASURED_ERROR_INDICES,
    measurement_information,
    measurement_matrix,
    pose_residual_kernel,
    predict_covariance_kernel,
    update_covariance_kernel,
)
from mavsysid.vehicle.dynamics import rk4_linear_step_kernel
from mavsysid.vehicle.linearization import (
    E_ATT,
    E_POS,
    E_THETA,
    MEAS_DIM,
    ErrorStateModel,
    initial_state_sigma,
)

#: The paper's model: 12 states and θ.
ERROR_DIM = E_THETA.stop

#: The agreement asked of the planner's covariance and the filter's, relative.
AGREEMENT = 1e-6
RATE = 100.0  # Hz, the pose measurement rate of the agreement test


def _residual(z: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = np.empty(MEAS_DIM)
    pose_residual_kernel(z, x, out)
    return out


def _random_covariance(rng: np.random.Generator, n: int) -> np.ndarray:
    """A symmetric positive definite matrix with entries of very different sizes."""
    L = rng.normal(size=(n, n)) * np.logspace(-4, 0, n)[:, None]
    return L @ L.T + 1e-9 * np.eye(n)


def test_measurement_matrix_selects_position_and_attitude_errors():
    """H has a unit entry at δp and δφ, in residual order, and nothing else."""
    H = measurement_matrix(ERROR_DIM)
    assert H.shape == (MEAS_DIM, ERROR_DIM)
    np.testing.assert_array_equal(np.flatnonzero(H.sum(axis=0)), MEASURED_ERROR_INDICES)
    np.testing.assert_array_equal(H[:, E_POS], np.vstack([np.eye(3), np.zeros((3, 3))]))
    np.testing.assert_array_equal(H[:, E_ATT], np.vstack([np.zeros((3, 3)), np.eye(3)]))
    assert H.sum() == MEAS_DIM


def test_measurement_matrix_matches_finite_differences(firefly, aggressive_trajectory):
    """H agrees with central finite differences of the residual of h(x ⊞ δx)."""
    model = ErrorStateModel.for_vehicle(firefly)
    rng = np.random.default_rng(3)
    flat = edge_samples(aggressive_trajectory, firefly, firefly.theta, 10.0)[0]
    H = measurement_matrix(ERROR_DIM)
    eps = 1e-6
    for x in flat[rng.choice(flat.shape[0], 10, replace=False)]:
        fd = np.empty((MEAS_DIM, ERROR_DIM))
        for i in range(ERROR_DIM):
            e = np.zeros(ERROR_DIM)
            e[i] = eps
            zp = model.measure(model.inject(x, firefly.theta, e)[0])
            zm = model.measure(model.inject(x, firefly.theta, -e)[0])
            fd[:, i] = (_residual(zp, x) - _residual(zm, x)) / (2 * eps)
        np.testing.assert_allclose(fd, H, atol=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernels_equal_the_dense_kalman_step(seed):
    """Predict and Joseph update by selection equal F P Fᵀ + Q and the dense-H Kalman step."""
    rng = np.random.default_rng(seed)
    P0 = _random_covariance(rng, ERROR_DIM)
    F = np.eye(ERROR_DIM) + 0.1 * rng.normal(size=(ERROR_DIM, ERROR_DIM))
    Q = _random_covariance(rng, ERROR_DIM)
    R = _random_covariance(rng, MEAS_DIM)
    P = P0.copy()
    predict_covariance_kernel(P, F, Q)
    prior = F @ P0 @ F.T + Q
    np.testing.assert_allclose(P, prior, rtol=1e-12, atol=1e-14 * np.abs(prior).max())
    S, SI, K = np.empty((6, 6)), np.empty((6, 6)), np.empty((ERROR_DIM, 6))
    update_covariance_kernel(P, R, S, SI, K)
    H = measurement_matrix(ERROR_DIM)
    S_ref = H @ prior @ H.T + R
    K_ref = prior @ H.T @ np.linalg.inv(S_ref)
    posterior = (np.eye(ERROR_DIM) - K_ref @ H) @ prior  # paper Eq. posterior (plain form)
    np.testing.assert_allclose(S, S_ref, rtol=1e-13)
    np.testing.assert_allclose(K, K_ref, rtol=1e-9, atol=1e-12 * np.abs(K_ref).max())
    np.testing.assert_allclose(P, posterior, rtol=1e-7, atol=1e-10 * np.abs(posterior).max())
    np.testing.assert_array_equal(P, P.T)
    np.testing.assert_allclose(measurement_information(R, ERROR_DIM), H.T @ np.linalg.inv(R) @ H,
                               rtol=1e-12)


# -- the planner's belief is the filter's covariance ----------------------------------


@pytest.fixture
def noisy_firefly(firefly):
    """The Firefly with process noise, so that Q as well as F and R shape the covariance."""
    return replace(firefly, noise=replace(firefly.noise, force_density=0.05,
                                          moment_density=0.005))


@pytest.fixture
def flown(noisy_firefly, aggressive_trajectory):
    """States flown by the model's RK4 from a flatness trajectory's rotor speeds.

    Returns (states (K + 1, 13), rotor speeds (K + 1, k), step s). The integrated states,
    not the flat ones, are the truth here, so that a filter fed their exact poses keeps
    its nominal state on them.
    """
    cfg = noisy_firefly
    flat, n, dt = edge_samples(aggressive_trajectory, cfg, cfg.theta, RATE)
    states = np.empty_like(flat)
    states[0] = flat[0]
    states[0, 6:10] /= np.linalg.norm(states[0, 6:10])
    zero = np.zeros(6)
    r, eps = np.ascontiguousarray(cfg.rotor_positions), np.ascontiguousarray(cfg.rotor_directions)
    for k in range(n.shape[0] - 1):
        rk4_linear_step_kernel(states[k], n[k], n[k + 1], zero, zero, cfg.theta, dt, cfg.mass,
                               r, eps, states[k + 1])
    return states, n, dt


def _filtered(config, states, n, dt):
    """The parameter EKF's P (K + 1, 18, 18) on exact poses of ``states``, θ at nominal."""
    theta = config.theta
    prior = ParameterEstimate(theta.copy(), np.diag((0.3 * theta) ** 2))
    ekf = ParameterEKF(config, prior, (config.noise.position_sigma, config.noise.attitude_sigma))
    sigma = initial_state_sigma(config.noise.position_sigma, config.noise.attitude_sigma, dt)
    x0 = states[0]
    ekf.initialize(x0[0:3], x0[6:10], x0[3:6], x0[10:13], sigma)
    out = np.empty((n.shape[0], ERROR_DIM, ERROR_DIM))
    out[0] = ekf.P
    for k in range(1, n.shape[0]):
        ekf.predict(n[k - 1], dt, n[k])
        ekf.update(np.concatenate([states[k, 0:3], states[k, 6:10]]))
        out[k] = ekf.P
    # The nominal stayed on the flown states, so the linearisation points were the same.
    np.testing.assert_allclose(ekf.x[:13], states[-1], atol=1e-9)
    np.testing.assert_allclose(ekf.theta, theta, rtol=1e-12)
    return out


def _disagreement(a: np.ndarray, b: np.ndarray) -> float:
    """max |a_ij − b_ij| / √(b_ii b_jj): relative to each entry's own scale, over all entries."""
    d = np.sqrt(np.diagonal(b, axis1=-2, axis2=-1))
    return float(np.max(np.abs(a - b) / (d[..., :, None] * d[..., None, :])))


@pytest.fixture
def filtered(noisy_firefly, flown):
    return _filtered(noisy_firefly, *flown)


def test_planner_covariance_is_the_filters(noisy_firefly, flown, filtered):
    """Planner and filter, same trajectory, θ and step: P agrees to 1e-6 relative at every step."""
    cfg = noisy_firefly
    states, n, dt = flown
    model = ErrorStateModel.for_vehicle(cfg)
    sigma0 = filtered[0]
    steps = propagate_steps(model, sigma0, states, n, cfg.theta, dt)
    assert _disagreement(steps, filtered) < AGREEMENT
    # The star-product path the planner searches with, after a quarter, half, … of the edge.
    K = n.shape[0] - 1
    for k in (K // 4, K // 2, 3 * K // 4, K):
        transfer = edge_transfer(model, states[:k + 1], n[:k + 1], cfg.theta, dt)
        assert _disagreement(apply_transfer(sigma0, transfer), filtered[k]) < AGREEMENT, k
    # The trajectory informs θ: the filter's θ σ has fallen well below the prior's.
    theta = slice(12, 18)
    assert np.all(np.diag(filtered[-1][theta, theta]) < 0.5 * np.diag(sigma0[theta, theta]))


@pytest.mark.parametrize(("what", "theta_factor", "step_factor"),
                         [("θ", 1.0 + 1e-4, 1.0), ("step", 1.0, 1.0 + 1e-4)])
def test_agreement_needs_the_same_theta_and_step(noisy_firefly, flown, filtered, what,
                                                 theta_factor, step_factor):
    """Linearised at a θ or with a step 0.01 % off, the planner misses the filter's P by > 1e-6."""
    cfg = noisy_firefly
    states, n, dt = flown
    theta = cfg.theta * theta_factor
    model = ErrorStateModel.for_vehicle(cfg)
    steps = propagate_steps(model, filtered[0], states, n, theta, dt * step_factor)
    transfer = edge_transfer(model, states, n, theta, dt * step_factor)
    assert _disagreement(steps, filtered) > 10 * AGREEMENT, what
    assert _disagreement(apply_transfer(filtered[0], transfer), filtered[-1]) > 10 * AGREEMENT
