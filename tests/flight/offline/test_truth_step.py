"""Tests of the simulated truth's step (`mavsysid.flight.offline.truth_step`)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.truth_step import advance_truth
from mavsysid.vehicle.allocation import rotor_speeds_squared
from mavsysid.vehicle.dynamics import ATT, STATE_DIM, hover_state, state_derivative
from mavsysid.vehicle.rotation import quat_exp, quat_multiply


def _joint_rk4(cfg, y, n_cmd, dt, tau, force, torque):
    """Classical RK4 of the joint truth state [x, n], ṅ = (n_cmd − n)/τ, written out."""

    def g(state):
        x, n = state[:STATE_DIM], state[STATE_DIM:]
        n_dot = (n_cmd - n) / tau if tau > 0.0 else np.zeros_like(n)
        return np.concatenate([state_derivative(x, n, cfg, None, force, torque), n_dot])

    if tau <= 0.0:
        y = np.concatenate([y[:STATE_DIM], n_cmd])
    k1 = g(y)
    k2 = g(y + 0.5 * dt * k1)
    k3 = g(y + 0.5 * dt * k2)
    k4 = g(y + dt * k3)
    out = y + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    out[ATT] /= np.linalg.norm(out[ATT])
    return out


@pytest.mark.parametrize("tau", [0.0, 0.02])
def test_truth_step_is_rk4_of_state_and_lagged_rotor_speeds(firefly, tau):
    """advance_truth equals one RK4 of [x, n] with the motor lag, effects' wrench included."""
    rng = np.random.default_rng(8)
    hover = np.sqrt(rotor_speeds_squared(np.array([firefly.hover_thrust, 0, 0, 0]), firefly))
    x = hover_state(np.array([0.1, 0.2, 1.0]), 0.4)
    x[3:6] = rng.normal(size=3)
    x[ATT] = quat_multiply(x[ATT], quat_exp(0.2 * rng.normal(size=3)))
    x[10:13] = rng.normal(size=3)
    y = np.concatenate([x, hover * (1.0 + 0.1 * rng.normal(size=firefly.rotor_count))])
    n_cmd = hover * (1.0 + 0.1 * rng.normal(size=firefly.rotor_count))
    force, torque = 0.3 * rng.normal(size=3), 0.02 * rng.normal(size=3)
    dt = 0.001
    expected = y.copy()
    for _ in range(3):
        expected = _joint_rk4(firefly, expected, n_cmd, dt, tau, force, torque)
    advance_truth(y, n_cmd, dt, 3, tau, firefly.theta, firefly.mass,
                  np.ascontiguousarray(firefly.rotor_positions),
                  np.ascontiguousarray(firefly.rotor_directions), force, torque)
    np.testing.assert_allclose(y, expected, rtol=1e-13, atol=1e-13)
    lagged = not np.allclose(y[STATE_DIM:], n_cmd)
    assert lagged == (tau > 0.0)
