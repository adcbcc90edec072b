"""Tests of the catalogue's wrench laws and how effects compose (`total_wrench`)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import (
    BodyDrag,
    EffectInputs,
    MotorLag,
    RotorDragLinear,
    RotorInertia,
    RotorSpeedLag,
    Wind,
    total_wrench,
)
from mavsysid.vehicle.rotation import quat_normalize, quat_to_matrix


def _inputs(seed: int, samples: int = 7) -> EffectInputs:
    config = load_vehicle("quad_x")
    rng = np.random.default_rng(seed)
    return EffectInputs(
        t=np.arange(samples) * 0.01, position=rng.normal(size=(samples, 3)),
        quaternion=quat_normalize(rng.normal(size=(samples, 4))),
        velocity=rng.normal(size=(samples, 3)), rates=rng.normal(size=(samples, 3)),
        rotor_speeds=rng.uniform(400.0, 900.0, (samples, config.rotor_count)),
        theta=config.theta, rotor_positions=config.rotor_positions)


@pytest.mark.parametrize("seed", [0, 1])
def test_rotor_drag_linear_is_rotorpys_drag_matrix(seed):
    """F_i = −n_i diag(k, k, k_z)(v + ω × r_i) at the hubs; torque Σ r_i × F_i."""
    inputs = _inputs(seed)
    k, k_z = 2e-4, 3e-4
    force, torque = RotorDragLinear(k=k, k_z=k_z).wrench(inputs)
    f_ref, m_ref = np.zeros_like(force), np.zeros_like(torque)
    for s in range(len(inputs.t)):
        for n, r in zip(inputs.rotor_speeds[s], inputs.rotor_positions, strict=True):
            f = -n * np.diag([k, k, k_z]) @ (inputs.velocity[s] + np.cross(inputs.rates[s], r))
            f_ref[s] += f
            m_ref[s] += np.cross(r, f)
    np.testing.assert_allclose(force, f_ref, rtol=1e-12)
    np.testing.assert_allclose(torque, m_ref, rtol=1e-12)
    # Without k_z the law is the in-plane one: no force along z_B.
    assert np.all(RotorDragLinear(k=k).wrench(inputs)[0][:, 2] == 0.0)


@pytest.mark.parametrize("airspeed_effect", [BodyDrag(k=0.03), RotorDragLinear(k=2e-4, k_z=1e-4)])
def test_wind_reaches_every_airspeed_effect(airspeed_effect):
    """With a wind in the model, body drag and linear rotor drag act on v_B − Rᵀ w."""
    inputs = _inputs(2)
    wind = Wind(x=1.5, y=-0.7)
    w_body = np.einsum("nji,j->ni", quat_to_matrix(inputs.quaternion), [1.5, -0.7, 0.0])
    air = EffectInputs(inputs.t, inputs.position, inputs.quaternion,
                       inputs.velocity - w_body, inputs.rates, inputs.rotor_speeds,
                       inputs.theta, inputs.rotor_positions)
    expected = [a + b for a, b in zip(wind.wrench(inputs), airspeed_effect.wrench(air),
                                      strict=True)]
    for effects in ([wind, airspeed_effect], [airspeed_effect, wind]):
        got = total_wrench(effects, inputs)
        np.testing.assert_allclose(got[0], expected[0], rtol=1e-12)
        np.testing.assert_allclose(got[1], expected[1], rtol=1e-12)
    still = airspeed_effect.wrench(inputs)
    assert not np.allclose(still[0], airspeed_effect.wrench(air)[0])
    np.testing.assert_array_equal(total_wrench([airspeed_effect], inputs)[0], still[0])


def test_rotor_inertia_is_the_reaction_of_spinning_the_rotors_up():
    """Yaw torque −J_r Σ ε_i ṅ_i with ṅ from the speeds' time series; no force, no roll/pitch."""
    config = load_vehicle("quad_x")
    t = np.arange(200) * 0.002
    rng = np.random.default_rng(3)
    slopes = rng.uniform(-500.0, 500.0, config.rotor_count)  # rad/s², each rotor ramping
    n = 600.0 + t[:, None] * slopes
    inputs = EffectInputs(t, np.zeros((200, 3)), np.tile([1.0, 0, 0, 0], (200, 1)),
                          np.zeros((200, 3)), np.zeros((200, 3)), n, config.theta,
                          config.rotor_positions, rotor_directions=config.rotor_directions)
    force, torque = RotorInertia(J_r=3e-5).wrench(inputs)
    assert np.all(force == 0.0) and np.all(torque[:, :2] == 0.0)
    expected = -3e-5 * float(np.dot(config.rotor_directions, slopes))
    assert abs(expected) > 0.0
    np.testing.assert_allclose(torque[:, 2], expected, rtol=1e-9)
    # Given rates are used as they are; without spin directions there is no torque.
    given = EffectInputs(t, inputs.position, inputs.quaternion, inputs.velocity,
                         inputs.rates, n, config.theta, config.rotor_positions,
                         rotor_directions=config.rotor_directions,
                         rotor_speed_rates=np.zeros_like(n))
    assert np.all(RotorInertia(J_r=3e-5).wrench(given)[1] == 0.0)
    blind = EffectInputs(t, inputs.position, inputs.quaternion, inputs.velocity,
                         inputs.rates, n, config.theta, config.rotor_positions)
    assert np.all(RotorInertia(J_r=3e-5).wrench(blind)[1] == 0.0)


@pytest.mark.parametrize("tau", [0.01, 0.03])
def test_rotor_speed_lag_inverts_the_sensors_lag(tau):
    """Lagging true speeds by τ (the sensor) and applying the effect gives the true speeds."""
    t = np.arange(2000) * 0.002
    true = 700.0 + 80.0 * np.sin(2.0 * np.pi * 1.5 * t)[:, None] * [1.0, -0.5, 0.8, -1.2]
    logged = MotorLag(tau=tau).acting_rotor_speeds(t, true)  # the same first-order lag
    assert np.abs(logged - true)[500:].max() > 0.5 * 80.0 * 2.0 * np.pi * 1.5 * tau
    acting = RotorSpeedLag(tau=tau).acting_rotor_speeds(t, logged)
    # Central differences of a 1.5 Hz sine at 500 Hz: error ≪ the lag's.
    np.testing.assert_allclose(acting[1:-1], true[1:-1], atol=0.05)
    # The step of the simulator's sensor is the same recursion.
    y = logged[0].copy()
    for i in range(1, 50):
        y = RotorSpeedLag(tau=tau).logged_step(t[i] - t[i - 1], y, true[i - 1], true[i])
    np.testing.assert_allclose(y, logged[49], rtol=1e-12)
