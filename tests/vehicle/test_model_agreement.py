"""The model's three users agree: the dynamics, the linearisation's nominal and the residuals.

All three call the laws of `mavsysid.vehicle.mav_model`; these tests hold them to one
another, and the shared laws to the paper's equations written out independently here,
on seeded random states, rotor speeds and θ (rotor drag and body velocity non-zero).
"""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.balance.rows import model_accelerations
from mavsysid.estimation.signals import SmoothedPose
from mavsysid.vehicle.config import GRAVITY, VehicleConfig
from mavsysid.vehicle.dynamics import RATE, STATE_DIM, VEL, state_derivative
from mavsysid.vehicle.linearization import E_RATE, E_THETA, E_VEL, ErrorStateModel
from mavsysid.vehicle.mav_model import (
    collective_thrust,
    euler_acceleration,
    rotor_thrust,
    rotor_wrench,
)
from mavsysid.vehicle.rotation import quat_normalize, quat_to_matrix

SAMPLES = 64
RTOL = 1e-10


def _random_case(config: VehicleConfig, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States (N, 13), rotor speeds (N, k) and θ (6,) drawn around the vehicle's nominal."""
    rng = np.random.default_rng(seed)
    x = np.zeros((SAMPLES, STATE_DIM))
    x[:, 0:3] = rng.normal(0.0, 2.0, (SAMPLES, 3))
    x[:, VEL] = rng.normal(0.0, 3.0, (SAMPLES, 3))
    x[:, 6:10] = quat_normalize(rng.normal(size=(SAMPLES, 4)))
    x[:, RATE] = rng.normal(0.0, 2.0, (SAMPLES, 3))
    n_max = config.limits.rotor_speed_max
    n = rng.uniform(0.2 * n_max, n_max, (SAMPLES, config.rotor_count))
    theta = config.theta * rng.uniform(0.5, 1.5, 6)
    theta[1] = rng.uniform(0.02, 0.2)  # rotor drag on, whatever the nominal
    return x, n, theta


def _close(actual: np.ndarray, expected: np.ndarray) -> None:
    """Equal to RTOL relative to the largest entry of each column (some entries are ~0)."""
    scale = np.max(np.abs(expected), axis=0, keepdims=True)
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=RTOL * float(np.max(scale)))


def _paper_wrench(n: np.ndarray, theta: np.ndarray, config: VehicleConfig, v: np.ndarray,
                  w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's rotor wrench (Eqs. drag, newton, euler) rotor by rotor, as an oracle."""
    c_T, c_D, c_M = theta[0], theta[1], theta[2]
    force = np.zeros((len(n), 3))
    torque = np.zeros((len(n), 3))
    drag = np.diag([c_D, c_D, 0.0])
    for i, (r_i, eps_i) in enumerate(zip(config.rotor_positions, config.rotor_directions,
                                         strict=True)):
        n2 = n[:, i] ** 2
        hub = v + np.cross(w, r_i)
        f_i = c_T * n2[:, None] * (np.array([0.0, 0.0, 1.0]) - hub @ drag.T)
        m_i = -eps_i * c_M * n2[:, None] * np.array([0.0, 0.0, 1.0])
        force += f_i
        torque += m_i + np.cross(r_i, f_i)
    return force, torque


def _dynamics_accelerations(x: np.ndarray, n: np.ndarray, theta: np.ndarray,
                            config: VehicleConfig) -> np.ndarray:
    """[F_B/m, ω̇] read off ẋ: F_B/m = v̇_B + ω × v_B − Rᵀ g (paper Eq. newton)."""
    xdot = state_derivative(x, n, config, theta)
    R = quat_to_matrix(x[:, 6:10])
    g_body = np.einsum("nji,j->ni", R, np.array([0.0, 0.0, -GRAVITY]))
    specific = xdot[:, VEL] + np.cross(x[:, RATE], x[:, VEL]) - g_body
    return np.hstack([specific, xdot[:, RATE]])


@pytest.mark.parametrize("seed", [0, 1])
def test_shared_wrench_matches_the_paper(any_vehicle: VehicleConfig, seed: int) -> None:
    """The shared rotor wrench and Euler's equation equal the paper's, written out apart."""
    x, n, theta = _random_case(any_vehicle, seed)
    v, w = x[:, VEL], x[:, RATE]
    force, torque = rotor_wrench(n, theta, any_vehicle.rotor_positions,
                                 any_vehicle.rotor_directions, v, w)
    expected_force, expected_torque = _paper_wrench(n, theta, any_vehicle, v, w)
    _close(force, expected_force)
    _close(torque, expected_torque)
    J = theta[3:6]
    _close(euler_acceleration(torque, w, J), (torque - np.cross(w, J * w)) / J)
    _close(collective_thrust(theta[0], n), expected_force[:, 2])
    _close(rotor_thrust(theta[0], n), theta[0] * n**2)


@pytest.mark.parametrize("seed", [0, 1])
def test_residual_model_agrees_with_dynamics(any_vehicle: VehicleConfig, seed: int) -> None:
    """The residual model's [F_B/m, ω̇] equals the dynamics' on random states."""
    x, n, theta = _random_case(any_vehicle, seed)
    R = quat_to_matrix(x[:, 6:10])
    zeros = np.zeros((SAMPLES, 3))
    pose = SmoothedPose(t=np.arange(SAMPLES) * 0.01, position=x[:, 0:3],
                        quaternion=x[:, 6:10], velocity=np.einsum("nij,nj->ni", R, x[:, VEL]),
                        acceleration=zeros, rates=x[:, RATE], angular_acceleration=zeros)
    residual_model = model_accelerations(pose, n, theta, any_vehicle)
    _close(residual_model, _dynamics_accelerations(x, n, theta, any_vehicle))


@pytest.mark.parametrize("seed", [0, 1])
def test_linearisation_nominal_agrees_with_dynamics(any_vehicle: VehicleConfig,
                                                    seed: int) -> None:
    """The linearisation's nominal ω̇ and rotor wrench equal the dynamics' on random states."""
    x, n, theta = _random_case(any_vehicle, seed)
    model = ErrorStateModel.for_vehicle(any_vehicle)
    A, _ = model.continuous(x, n, np.broadcast_to(theta, (SAMPLES, 6)))
    s = model.theta_scale
    J = theta[3:6]
    rates, thetas = np.arange(3) + E_RATE.start, np.arange(3) + E_THETA.start + 3
    # ∂(J⁻¹(M − ω × Jω))_a/∂j_a = −ω̇_a / j_a: the J block's diagonal holds the nominal ω̇.
    omega_dot = -A[:, rates, thetas] * J / s[3:6]
    # The wrench is homogeneous in (c_T, c_M): F = c_T ∂F/∂c_T, M = c_T ∂M/∂c_T + c_M ∂M/∂c_M.
    specific = theta[0] * A[:, E_VEL, E_THETA.start] / s[0]
    torque = (theta[0] * A[:, E_RATE, E_THETA.start] / s[0]
              + theta[2] * A[:, E_RATE, E_THETA.start + 2] / s[2]) * J
    expected = _dynamics_accelerations(x, n, theta, any_vehicle)
    _close(np.hstack([specific, omega_dot]), expected)
    _, expected_torque = _paper_wrench(n, theta, any_vehicle, x[:, VEL], x[:, RATE])
    _close(torque, expected_torque)
