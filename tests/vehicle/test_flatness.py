"""Tests of differential flatness: flat outputs → state, thrust and rotor speeds."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.allocation import allocation_matrix
from mavsysid.vehicle.config import GRAVITY
from mavsysid.vehicle.dynamics import ATT, POS, VEL, state_derivative
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.rotation import quat_conjugate, quat_log, quat_multiply, quat_to_matrix
from mavsysid.vehicle.trajectory import FlatOutputs


def _flat_at(traj, t, cfg):
    return flat_to_state(traj.flat_outputs(np.atleast_1d(t)), cfg)


def test_aggressive_trajectory_is_aggressive_and_feasible(firefly, aggressive_trajectory):
    """The test figure reaches ≥ 1 g lateral, ≥ 45° tilt, ≥ 3 rad/s, within rotor limits."""
    t = np.linspace(0.0, aggressive_trajectory.duration, 3001)
    flat = aggressive_trajectory.flat_outputs(t)
    state = flat_to_state(flat, firefly)
    lateral = np.linalg.norm(flat.acceleration[:, :2], axis=1)
    tilt = np.degrees(np.arccos(state.rotation[:, 2, 2]))
    assert lateral.max() >= GRAVITY
    assert tilt.max() >= 45.0
    assert np.linalg.norm(state.body_rates, axis=1).max() >= 3.0
    ratio = state.thrust / firefly.hover_thrust
    assert firefly.limits.thrust_min_ratio <= ratio.min()
    assert ratio.max() <= firefly.limits.thrust_max_ratio
    assert state.rotor_speeds_squared.min() > 0.0
    assert state.rotor_speeds.max() < firefly.limits.rotor_speed_max


def test_open_loop_round_trip_reproduces_the_trajectory(firefly, aggressive_trajectory):
    """Flatness speeds at RK4 stage times, fed open-loop at 1 kHz, end < 1 cm and < 0.5° off."""
    theta = firefly.theta.copy()
    theta[1] = 0.0  # drag-free, as flatness assumes
    dt = 1e-3
    steps = round(aggressive_trajectory.duration / dt)
    t = np.arange(steps) * dt
    # n at t, t + dt/2 and t + dt for every step, computed in one vectorised call.
    stage_t = np.stack([t, t + dt / 2, t + dt], axis=1).ravel()
    n = _flat_at(aggressive_trajectory, stage_t, firefly).rotor_speeds.reshape(steps, 3, -1)
    x = _flat_at(aggressive_trajectory, 0.0, firefly).states()[0]

    def f(state, speeds):
        return state_derivative(state, speeds, firefly, theta)

    for i in range(steps):
        k1 = f(x, n[i, 0])
        k2 = f(x + dt / 2 * k1, n[i, 1])
        k3 = f(x + dt / 2 * k2, n[i, 1])
        k4 = f(x + dt * k3, n[i, 2])
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        x[ATT] /= np.linalg.norm(x[ATT])

    end = _flat_at(aggressive_trajectory, aggressive_trajectory.duration, firefly).states()[0]
    assert np.linalg.norm(x[POS] - end[POS]) < 0.01
    angle = np.linalg.norm(quat_log(quat_multiply(quat_conjugate(end[ATT]), x[ATT])))
    assert np.degrees(angle) < 0.5


def test_flat_state_satisfies_the_dynamics(any_vehicle, aggressive_trajectory):
    """f at the flat state and flatness speeds reproduces the reference a and ω̇."""
    theta = any_vehicle.theta.copy()
    theta[1] = 0.0
    t = np.linspace(0.0, aggressive_trajectory.duration, 301)
    flat = aggressive_trajectory.flat_outputs(t)
    state = flat_to_state(flat, any_vehicle)
    ok = state.rotor_speeds_squared.min(axis=1) >= 0.0  # small vehicles may not fly all of it
    xdot = state_derivative(state.states()[ok], state.rotor_speeds[ok], any_vehicle, theta)
    v_b = state.velocity_body[ok]
    acc_world = np.einsum("sij,sj->si", state.rotation[ok],
                          xdot[:, VEL] + np.cross(state.body_rates[ok], v_b))
    np.testing.assert_allclose(acc_world, flat.acceleration[ok], atol=1e-9)
    np.testing.assert_allclose(xdot[:, 10:13], state.angular_acceleration[ok], atol=1e-8)


def test_body_rates_and_angular_acceleration_are_derivatives(firefly, aggressive_trajectory):
    """ω matches the attitude's time derivative and ω̇ the derivative of ω (central FD)."""
    t = np.linspace(0.2, 2.8, 27)
    h = 1e-5
    s0 = _flat_at(aggressive_trajectory, t, firefly)
    sp = _flat_at(aggressive_trajectory, t + h, firefly)
    sm = _flat_at(aggressive_trajectory, t - h, firefly)
    # Body rates from R(t+h) ≈ R(t) Exp(ω h): ω ≈ Log(q(t-h)⁻¹ q(t+h)) / 2h.
    omega_fd = quat_log(quat_multiply(quat_conjugate(sm.quaternion), sp.quaternion)) / (2 * h)
    np.testing.assert_allclose(omega_fd, s0.body_rates, atol=1e-6)
    np.testing.assert_allclose((sp.body_rates - sm.body_rates) / (2 * h),
                               s0.angular_acceleration, atol=1e-5)


@pytest.mark.parametrize("yaw", [0.0, 2.0, -3.0])
def test_hover_flat_state_is_level_with_given_yaw(firefly, yaw):
    """A resting flat state maps to level attitude with the requested yaw and hover thrust."""
    from mavsysid.vehicle.trajectory import FlatOutputs

    z = np.zeros((1, 3))
    flat = FlatOutputs(z + [1, 2, 3], z, z, z, z, np.array([yaw]), np.zeros(1), np.zeros(1))
    state = flat_to_state(flat, firefly)
    R = state.rotation[0]
    np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.arctan2(R[1, 0], R[0, 0]), yaw, atol=1e-12)
    np.testing.assert_allclose(state.thrust, firefly.hover_thrust)
    np.testing.assert_allclose(state.body_rates, 0.0, atol=1e-12)


def _random_flat(seed: int, samples: int, acceleration: float) -> FlatOutputs:
    rng = np.random.default_rng(seed)

    def vectors(scale: float) -> np.ndarray:
        return rng.normal(0.0, scale, (samples, 3))

    return FlatOutputs(vectors(1.0), vectors(2.0), vectors(acceleration), vectors(20.0),
                       vectors(100.0), rng.uniform(-np.pi, np.pi, samples),
                       rng.normal(0.0, 2.0, samples), rng.normal(0.0, 5.0, samples))


@pytest.mark.parametrize("acceleration", [3.0, 30.0])
def test_quaternion_is_the_rotation_and_sign_continuous(firefly, acceleration):
    """q reproduces R (upright and inverted attitudes alike), |q| = 1, q_0 has w ≥ 0, and
    consecutive quaternions lie in the same hemisphere."""
    state = flat_to_state(_random_flat(3, 400, acceleration), firefly)
    q = state.quaternion
    np.testing.assert_allclose(quat_to_matrix(q), state.rotation, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    assert q[0, 0] >= 0.0
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) >= 0.0)
    if acceleration > GRAVITY:  # the draw holds inverted attitudes (rotations near π)
        assert state.rotation[:, 2, 2].min() < -0.9


def test_singular_attitude_is_nan_only_at_its_sample(firefly):
    """Free fall (a = g) has no thrust direction: that sample is NaN, its neighbours are not."""
    flat = _random_flat(4, 5, 1.0)
    flat.acceleration[2] = [0.0, 0.0, -GRAVITY]
    state = flat_to_state(flat, firefly)
    assert np.all(np.isnan(state.quaternion[2])) and np.all(np.isnan(state.rotor_speeds_squared[2]))
    others = [0, 1, 3, 4]
    for field in (state.quaternion, state.rotation, state.body_rates, state.rotor_speeds_squared):
        assert np.all(np.isfinite(field[others]))


def test_rotor_speeds_follow_theta(firefly):
    """n² is A(θ)⁺ [T, τ] for the θ passed in, not a cached θ of an earlier call."""
    flat = _random_flat(5, 20, 3.0)
    for scale in (1.0, 0.6, 1.4, 1.0):
        theta = firefly.theta * scale
        state = flat_to_state(flat, firefly, theta)
        wrench = np.column_stack([state.thrust, state.torque])
        np.testing.assert_allclose(state.rotor_speeds_squared @ allocation_matrix(firefly, theta).T,
                                   wrench, rtol=1e-9, atol=1e-9 * firefly.hover_thrust)
