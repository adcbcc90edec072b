"""The ideal IMU reading (`mavsysid.vehicle.imu`) against the model's own laws."""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.dynamics import state_derivative
from mavsysid.vehicle.imu import imu_reading, lever_arm_acceleration
from mavsysid.vehicle.mav_model import euler_acceleration, rotor_wrench
from mavsysid.vehicle.rotation import quat_to_matrix


def test_reading_is_the_force_per_mass_plus_the_lever_arm() -> None:
    """gyro = ω; accel = (F_rotors + F_ext)/m + ω̇ × p + ω × (ω × p), ω̇ from Euler's
    equation, for a batch of random states; and at the CoG the specific force is
    v̇_B + ω × v_B − Rᵀ g of the dynamics."""
    config = load_vehicle("firefly")
    rng = np.random.default_rng(4)
    x = rng.normal(size=(50, 13))
    x[:, 6:10] /= np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    n = rng.uniform(300.0, 800.0, (50, 6))
    f_ext, m_ext = rng.normal(size=(50, 3)), rng.normal(scale=0.1, size=(50, 3))
    p = np.array([0.03, -0.02, 0.05])
    theta, r, eps = config.theta, config.rotor_positions, config.rotor_directions
    gyro, accel = imu_reading(x, n, theta, config.mass, r, eps, f_ext, m_ext, p)
    force, torque = rotor_wrench(n, theta, r, eps, x[:, 3:6], x[:, 10:13])
    w_dot = euler_acceleration(torque + m_ext, x[:, 10:13], theta[3:6])
    expected = (force + f_ext) / config.mass + lever_arm_acceleration(x[:, 10:13], w_dot, p)
    np.testing.assert_allclose(gyro, x[:, 10:13], rtol=0, atol=0)
    np.testing.assert_allclose(accel, expected, rtol=1e-12, atol=1e-12)
    _, at_cog = imu_reading(x, n, theta, config.mass, r, eps)
    dx = state_derivative(x, n, config, theta)
    R = quat_to_matrix(x[:, 6:10])
    from_motion = (dx[:, 3:6] + np.cross(x[:, 10:13], x[:, 3:6])
                   + np.einsum("nji,j->ni", R, [0.0, 0.0, 9.81]))
    np.testing.assert_allclose(at_cog, from_motion, rtol=1e-9, atol=1e-9)
