"""Tests of the continuous dynamics ẋ = f(x, u, θ)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv, rotor_speeds_squared
from mavsysid.vehicle.config import GRAVITY
from mavsysid.vehicle.dynamics import (
    ATT,
    POS,
    RATE,
    VEL,
    hover_state,
    rk4_linear_step_kernel,
    rk4_step_kernel,
    state_derivative,
)
from mavsysid.vehicle.rotation import quat_exp, quat_multiply, quat_to_matrix


def _hover_speeds(cfg, theta=None):
    return np.sqrt(rotor_speeds_squared(np.array([cfg.hover_thrust, 0, 0, 0]), cfg, theta))


@pytest.mark.parametrize("yaw", [0.0, 1.3, -2.9])
def test_hover_has_no_acceleration(any_vehicle, yaw):
    """Level and at rest, allocation-computed hover speeds give |ẋ| < 1e-9."""
    x = hover_state(np.array([0.3, -1.0, 2.0]), yaw)
    xdot = state_derivative(x, _hover_speeds(any_vehicle), any_vehicle)
    assert np.max(np.abs(xdot)) < 1e-9


def test_free_fall_accelerates_at_gravity(any_vehicle):
    """With rotors stopped the world acceleration is g at any attitude, and ω̇ = 0."""
    rng = np.random.default_rng(4)
    for _ in range(5):
        x = hover_state()
        x[ATT] = quat_exp(rng.normal(size=3))
        x[VEL] = rng.normal(size=3)
        xdot = state_derivative(x, np.zeros(any_vehicle.rotor_count), any_vehicle)
        R = quat_to_matrix(x[ATT])
        # v̇_B = Rᵀ g - ω × v_B with ω = 0, so R v̇_B = g.
        np.testing.assert_allclose(R @ xdot[VEL], [0, 0, -GRAVITY], atol=1e-12)
        np.testing.assert_allclose(xdot[POS], R @ x[VEL], atol=1e-12)
        np.testing.assert_allclose(xdot[RATE], 0.0, atol=1e-12)


def test_pure_yaw_torque_spins_only_about_z(any_vehicle):
    """Speeds for [mg, 0, 0, τ] give ω̇ = (0, 0, τ / j_z) and no linear acceleration."""
    arm = np.mean(np.linalg.norm(any_vehicle.rotor_positions, axis=1))
    tau = 0.02 * any_vehicle.hover_thrust * arm
    n = np.sqrt(rotor_speeds_squared(np.array([any_vehicle.hover_thrust, 0, 0, tau]), any_vehicle))
    xdot = state_derivative(hover_state(), n, any_vehicle)
    j_z = any_vehicle.parameters.J[2]
    np.testing.assert_allclose(xdot[RATE], [0, 0, tau / j_z], rtol=1e-9, atol=1e-9 * tau / j_z)
    np.testing.assert_allclose(xdot[VEL], 0.0, atol=1e-9)


def test_constant_yaw_rate_rotates_the_quaternion_about_z(firefly):
    """q̇ = ½ q ⊗ [0, ω]: integrating a pure yaw rate gives the yaw quaternion."""
    r, T, steps = 0.7, 1.0, 2000
    x = hover_state(yaw=0.2)
    x[RATE] = [0, 0, r]
    n = _hover_speeds(firefly)
    dt = T / steps
    for _ in range(steps):  # midpoint rule on the quaternion only
        half = x.copy()
        half[ATT] += 0.5 * dt * state_derivative(x, n, firefly)[ATT]
        x[ATT] += dt * state_derivative(half, n, firefly)[ATT]
    expected = quat_multiply(hover_state(yaw=0.2)[ATT], quat_exp(np.array([0, 0, r * T])))
    np.testing.assert_allclose(x[ATT], expected, atol=1e-6)


@pytest.mark.parametrize("v_body", [[1.0, 0.0, 0.0], [0.0, -2.0, 0.0], [1.5, 0.7, 0.0]])
def test_rotor_drag_opposes_body_velocity(any_vehicle, v_body):
    """At hover thrust, drag adds -c_D T v_B / m in the rotor plane, opposing the motion."""
    x = hover_state()
    x[VEL] = v_body
    n = _hover_speeds(any_vehicle)
    xdot = state_derivative(x, n, any_vehicle)
    v = np.asarray(v_body)
    drag_acc = xdot[VEL]  # gravity and thrust cancel; ω = 0
    assert drag_acc @ v < 0.0
    expected = -any_vehicle.parameters.c_D * any_vehicle.hover_thrust * v / any_vehicle.mass
    np.testing.assert_allclose(drag_acc, expected, rtol=1e-9, atol=1e-12)


def test_vertical_velocity_feels_no_rotor_drag(firefly):
    """Rotor drag acts in the rotor plane only: a climb at hover thrust is unopposed."""
    x = hover_state()
    x[VEL] = [0, 0, 2.0]
    xdot = state_derivative(x, _hover_speeds(firefly), firefly)
    np.testing.assert_allclose(xdot[VEL], 0.0, atol=1e-12)


def test_drag_of_rotation_uses_hub_velocity(firefly):
    """A yaw rate moves each hub sideways (ω × r_i): drag then brakes the yaw rotation."""
    x = hover_state()
    x[RATE] = [0, 0, 2.0]
    xdot = state_derivative(x, _hover_speeds(firefly), firefly)
    assert xdot[RATE][2] < 0.0
    np.testing.assert_allclose(xdot[VEL], 0.0, atol=1e-12)


def test_batch_matches_single_states(firefly):
    """The array wrapper gives the same ẋ as one state at a time."""
    rng = np.random.default_rng(7)
    X = np.tile(hover_state(), (5, 1))
    X[:, VEL] = rng.normal(size=(5, 3))
    X[:, ATT] = quat_exp(rng.normal(size=(5, 3)))
    X[:, RATE] = rng.normal(size=(5, 3))
    N = 500 + 50 * rng.normal(size=(5, 6))
    batch = state_derivative(X, N, firefly)
    for i in range(5):
        np.testing.assert_array_equal(batch[i], state_derivative(X[i], N[i], firefly))


def _moving_state(rng: np.random.Generator) -> np.ndarray:
    x = hover_state(np.array([0.2, -0.4, 1.5]), 0.7)
    x[VEL] = rng.normal(size=3)
    x[ATT] = quat_multiply(x[ATT], quat_exp(0.3 * rng.normal(size=3)))
    x[RATE] = rng.normal(size=3)
    return x


def test_rk4_step_is_the_classical_scheme(firefly):
    """rk4_step_kernel is classical RK4 on f with the given stage inputs, q renormalised."""
    rng = np.random.default_rng(3)
    x = _moving_state(rng)
    n = _hover_speeds(firefly) * (1.0 + 0.1 * rng.normal(size=(4, firefly.rotor_count)))
    w = 0.1 * rng.normal(size=(4, 6))
    dt = 0.01

    def f(state, s):
        return state_derivative(state, n[s], firefly, None, w[s, :3], w[s, 3:])

    k1 = f(x, 0)
    k2 = f(x + 0.5 * dt * k1, 1)
    k3 = f(x + 0.5 * dt * k2, 2)
    k4 = f(x + dt * k3, 3)
    expected = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    expected[ATT] /= np.linalg.norm(expected[ATT])
    out = np.empty(13)
    rk4_step_kernel(x, n, w, firefly.theta, dt, firefly.mass, firefly.rotor_positions,
                    firefly.rotor_directions, out)
    np.testing.assert_allclose(out, expected, rtol=1e-14, atol=1e-15)


def test_rk4_is_fourth_order_with_linear_inputs(firefly):
    """With rotor speeds and wrench linear in time, halving the step cuts the error ~16×."""
    rng = np.random.default_rng(4)
    x0 = _moving_state(rng)
    n0 = _hover_speeds(firefly) * (1.0 + 0.1 * rng.normal(size=firefly.rotor_count))
    n1 = _hover_speeds(firefly) * (1.0 + 0.1 * rng.normal(size=firefly.rotor_count))
    w0, w1 = 0.2 * rng.normal(size=6), 0.2 * rng.normal(size=6)
    T = 0.2

    def fly(steps: int) -> np.ndarray:
        x = x0.copy()
        out = np.empty(13)
        for i in range(steps):
            a, b = i / steps, (i + 1) / steps
            rk4_linear_step_kernel(x, n0 + a * (n1 - n0), n0 + b * (n1 - n0),
                                   w0 + a * (w1 - w0), w0 + b * (w1 - w0), firefly.theta,
                                   T / steps, firefly.mass, firefly.rotor_positions,
                                   firefly.rotor_directions, out)
            x = out.copy()
        return x

    exact = fly(512)
    errors = [np.abs(fly(steps) - exact).max() for steps in (4, 8, 16)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 12.0) & (ratios < 20.0)), ratios


def test_allocation_matrix_shape_and_rank(any_vehicle):
    """A is 4×k with full row rank, so thrust and all three torques are controllable."""
    A = allocation_matrix(any_vehicle)
    assert A.shape == (4, any_vehicle.rotor_count)
    assert np.linalg.matrix_rank(A) == 4


def test_allocation_pseudo_inverse_reproduces_wrench(any_vehicle):
    """A A⁺ w = w: n² from the pseudo-inverse produce exactly the requested wrench."""
    w = np.array([any_vehicle.hover_thrust * 1.2, 0.01, -0.02, 0.003])
    n2 = rotor_speeds_squared(w, any_vehicle)
    np.testing.assert_allclose(allocation_matrix(any_vehicle) @ n2, w, rtol=1e-12, atol=1e-15)


def test_allocation_pinv_is_the_callers_own_array(firefly):
    """A⁺ is computed once per θ but every call gets its own copy: writing to one changes
    nothing for the next caller."""
    first = allocation_pinv(firefly)
    expected = np.linalg.pinv(allocation_matrix(firefly))
    np.testing.assert_array_equal(first, expected)
    first[:] = 0.0
    np.testing.assert_array_equal(allocation_pinv(firefly), expected)
