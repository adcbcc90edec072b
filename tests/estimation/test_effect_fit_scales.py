"""The effect fit's units follow the vehicle: a Crazyflie-class drag is fitted, not blown up."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import EstimatorSettings, estimate_with_effects
from mavsysid.estimation.filter.likelihood import fit_scales
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.vehicle.config import GRAVITY, load_vehicle
from mavsysid.vehicle.model_effects import MarkerOffset, MotorLag, RotorDragLinear


@pytest.mark.parametrize(("effect", "expected"), [
    (RotorDragLinear(k=4e-7, k_z=-3e-7), [4e-7, 4e-7]),      # the effect's own size
    (MarkerOffset(x=0.0003, y=-0.02, z=0.01), [0.02, 0.02, 0.02]),
    (MotorLag(tau=0.0), [0.02]),                              # a zero start: the catalogue's
    (RotorDragLinear(k=1e-9), [1e-4, 1e-4]),                  # below 10⁻³ of it, too
])
def test_fit_units_are_the_size_of_the_start(effect, expected):
    """Each parameter is fitted in units of its effect's largest starting value."""
    np.testing.assert_allclose(fit_scales(effect), expected)


def test_micro_quad_linear_rotor_drag_is_fitted_with_its_inflow_term(simulate_flight):
    """micro_quad flying RotorPy's drag law (c_D = 0, k and k_z linear in n): the joint
    fit from a start 25 % off holds k and k_z in their 95 % intervals."""
    config = load_vehicle("micro_quad")
    c_t = config.theta[0]
    n_h = np.sqrt(config.mass * GRAVITY / (config.rotor_count * c_t))
    k, k_z = c_t * config.theta[1] * n_h, 0.75 * c_t * config.theta[1] * n_h
    truth = config.with_parameters(config.theta * np.array([1, 0, 1, 1, 1, 1]))
    flight = simulate_flight(truth, 5, effects=[hidden_effect(RotorDragLinear(k=k, k_z=k_z))])
    start = RotorDragLinear(k=1.25 * k, k_z=0.75 * k_z)
    result = estimate_with_effects(flight, config, [start], EstimatorSettings(refine=False))
    (fitted,) = result.effects
    lo, hi = fitted.ci95
    assert np.all((lo <= [k, k_z]) & ([k, k_z] <= hi)), (fitted.value, fitted.ci95)
    assert np.all(fitted.sigma < 0.1 * np.array([k, k_z]))
