"""Tests of the error-state linearisation shared by the planner and the EKF."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.dynamics import ATT, RATE, state_derivative
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.linearization import (
    E_ATT,
    E_POS,
    E_RATE,
    E_THETA,
    E_VEL,
    ErrorStateModel,
)
from mavsysid.vehicle.rotation import quat_conjugate, quat_exp, quat_multiply, quat_to_matrix

#: The paper's model: 12 states and θ.
ERROR_DIM = E_THETA.stop

_BLOCKS = (E_POS, E_VEL, E_ATT, E_RATE, E_THETA)


def _error_rate(model, x, theta, n, dx):
    """δẋ of the error state δx about (x, θ), from f alone (no Jacobian involved)."""
    cfg = model.config
    xp, thp = model.inject(x, theta, dx)
    f0 = state_derivative(x, n, cfg, theta)
    f1 = state_derivative(xp, n, cfg, thp)
    out = np.zeros(ERROR_DIM)
    out[E_POS] = f1[0:3] - f0[0:3]
    out[E_VEL] = f1[3:6] - f0[3:6]
    out[E_RATE] = f1[RATE] - f0[RATE]
    # e = q̂⁻¹ q = Exp(δφ) moves with body rate ξ = ω - R(e)ᵀ ω̂, where each ω is
    # read off f's own q̇ as 2 vec(q⁻¹ q̇); then δφ̇ = J_r⁻¹(δφ) ξ ≈ ξ + ½ δφ × ξ.
    w1 = 2.0 * quat_multiply(quat_conjugate(xp[ATT]), f1[ATT])[1:]
    w0 = 2.0 * quat_multiply(quat_conjugate(x[ATT]), f0[ATT])[1:]
    e = quat_multiply(quat_conjugate(x[ATT]), xp[ATT])
    xi = w1 - quat_to_matrix(e).T @ w0
    out[E_ATT] = xi + 0.5 * np.cross(dx[E_ATT], xi)
    return out


def _random_linearisation_points(cfg, trajectory, count, seed):
    """States along an aggressive trajectory, perturbed, with perturbed speeds and θ."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, trajectory.duration, count)
    flat = flat_to_state(trajectory.flat_outputs(t), cfg)
    X = flat.states()
    X[:, 3:6] += 0.3 * rng.normal(size=(count, 3))
    X[:, RATE] += 0.3 * rng.normal(size=(count, 3))
    N = flat.rotor_speeds * (1.0 + 0.05 * rng.normal(size=flat.rotor_speeds.shape))
    Th = cfg.theta * (1.0 + 0.3 * rng.uniform(-1.0, 1.0, size=(count, 6)))
    return X, N, Th


def test_dynamics_jacobian_matches_finite_differences(any_vehicle, aggressive_trajectory):
    """A agrees with central finite differences of f to relative error < 1e-5 at 20 states."""
    model = ErrorStateModel.for_vehicle(any_vehicle)
    X, N, Th = _random_linearisation_points(any_vehicle, aggressive_trajectory, 20, seed=11)
    A, _ = model.continuous(X, N, Th)
    eps = 1e-6
    worst = 0.0
    for j in range(X.shape[0]):
        fd = np.empty((ERROR_DIM, ERROR_DIM))
        for i in range(ERROR_DIM):
            e = np.zeros(ERROR_DIM)
            e[i] = eps
            fd[:, i] = (_error_rate(model, X[j], Th[j], N[j], e)
                        - _error_rate(model, X[j], Th[j], N[j], -e)) / (2 * eps)
        for rows in _BLOCKS:  # per row block, so small blocks are not hidden by big ones
            for i in range(ERROR_DIM):
                ref = np.linalg.norm(fd[rows, i])
                err = np.linalg.norm(A[j][rows, i] - fd[rows, i])
                floor = 1e-10 * np.linalg.norm(fd[:, i]) + 1e-12
                if ref > floor:
                    worst = max(worst, err / ref)
                else:
                    assert err <= 1e-5 * floor + 1e-9, (j, rows, i)
    assert worst < 1e-5


def test_inject_and_difference_are_inverse(firefly):
    """(x ⊞ δx) ⊟ x = δx for small and large attitude errors."""
    model = ErrorStateModel.for_vehicle(firefly)
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.normal(size=6), quat_exp(rng.normal(size=3)), rng.normal(size=3)])
    for scale in (1e-6, 0.1, 1.0):
        dx = scale * rng.normal(size=ERROR_DIM)
        x2, th2 = model.inject(x, firefly.theta, dx)
        np.testing.assert_allclose(model.difference(x2, th2, x, firefly.theta), dx, atol=1e-12)


def test_discrete_transition_converges_to_the_flow(firefly, aggressive_trajectory):
    """F_k matches the linearised RK4 flow over dt; its error shrinks ~dt² as dt halves."""
    model = ErrorStateModel.for_vehicle(firefly)
    X, N, Th = _random_linearisation_points(firefly, aggressive_trajectory, 3, seed=8)

    def flow(x, th, n, dt):
        k1 = state_derivative(x, n, firefly, th)
        k2 = state_derivative(x + dt / 2 * k1, n, firefly, th)
        k3 = state_derivative(x + dt / 2 * k2, n, firefly, th)
        k4 = state_derivative(x + dt * k3, n, firefly, th)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def error(j, dt):
        F, _ = model.discrete(X[j], N[j], Th[j], dt)
        x1 = flow(X[j], Th[j], N[j], dt)
        eps = 1e-6
        fd = np.empty((ERROR_DIM, ERROR_DIM))
        for i in range(ERROR_DIM):
            e = np.zeros(ERROR_DIM)
            e[i] = eps
            cols = []
            for sign in (1, -1):
                xp, thp = model.inject(X[j], Th[j], sign * e)
                cols.append(model.difference(flow(xp, thp, N[j], dt), thp, x1, Th[j]))
            fd[:, i] = (cols[0] - cols[1]) / (2 * eps)
        return np.linalg.norm(F - fd), np.linalg.norm(fd - np.eye(ERROR_DIM))

    for j in range(3):
        (e1, step1), (e2, _) = error(j, 0.01), error(j, 0.005)
        assert e1 < 0.05 * step1  # F_k - I is right to a few percent at 100 Hz
        assert 3.0 < e1 / e2 < 5.0  # and the local error is second order in dt


def test_process_noise_is_symmetric_positive_semidefinite(firefly, aggressive_trajectory):
    """Q_k is symmetric PSD and acts only on velocity, attitude and rate errors."""
    model = ErrorStateModel.for_vehicle(firefly)
    X, N, Th = _random_linearisation_points(firefly, aggressive_trajectory, 5, seed=2)
    _, Q = model.discrete(X, N, Th, 0.01)
    np.testing.assert_allclose(Q, np.swapaxes(Q, -1, -2), atol=1e-18)
    assert np.linalg.eigvalsh(Q).min() > -1e-15
    assert np.all(Q[:, E_THETA, :] == 0.0)


@pytest.mark.parametrize("factor", [0.5, 3.0])
def test_parameter_scale_only_rescales_parameter_columns(firefly, aggressive_trajectory, factor):
    """Changing the θ units multiplies A's θ columns by the factor and nothing else."""
    X, N, Th = _random_linearisation_points(firefly, aggressive_trajectory, 4, seed=9)
    base = ErrorStateModel.for_vehicle(firefly)
    scaled = ErrorStateModel.for_vehicle(firefly, factor * base.theta_scale)
    A1, _ = base.continuous(X, N, Th)
    A2, _ = scaled.continuous(X, N, Th)
    np.testing.assert_allclose(A2[..., E_THETA], factor * A1[..., E_THETA], rtol=1e-12)
    np.testing.assert_array_equal(A2[..., :12], A1[..., :12])
    P = np.eye(ERROR_DIM)
    np.testing.assert_allclose(scaled.parameter_covariance_si(P / factor**2),
                               base.parameter_covariance_si(P), rtol=1e-12)


def test_measurement_noise_matches_config(firefly):
    """R holds the configured motion-capture σ² on position and attitude."""
    R = ErrorStateModel.for_vehicle(firefly).measurement_covariance()
    np.testing.assert_allclose(np.diag(R)[:3], firefly.noise.position_sigma**2)
    np.testing.assert_allclose(np.diag(R)[3:], firefly.noise.attitude_sigma**2)
