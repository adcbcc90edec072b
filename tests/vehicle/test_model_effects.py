"""Tests of the catalogue's wrench laws and how effects compose (`total_wrench`)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import (
    BodyDrag,
    EffectInputs,
    RotorDragLinear,
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
