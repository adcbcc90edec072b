"""Model effects in the estimator: hidden effects recovered with θ, and no-effect equality."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    estimate_parameters,
    estimate_with_effects,
)
from mavsysid.estimation.flight import FlightData
from mavsysid.flight.offline.effects import ProcessNoise, hidden_effect
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import BodyDrag, MotorLag, PoseDelay, Wind

from mavsysid.errors import InputError

GOLDEN = Path(__file__).parent / "golden" / "no_effects_regression"
FILTER_ONLY = EstimatorSettings(refine=False)


def _noisy_firefly():
    """Firefly whose config noise densities equal the process noise the truth injects."""
    cfg = load_vehicle("firefly")
    return replace(cfg, noise=replace(cfg.noise, force_density=0.02 * cfg.mass,
                                      moment_density=0.02 * float(np.mean(cfg.parameters.J))))


def _hidden_flight(simulate_flight, effect, seed=1):
    cfg = _noisy_firefly()
    noise = ProcessNoise(cfg.noise.force_density, cfg.noise.moment_density, seed=500 + seed)
    return cfg, simulate_flight(cfg, seed, effects=[hidden_effect(effect), noise])


def _prior(cfg):
    return cfg.with_parameters(cfg.theta * np.array([1.3, 0.6, 0.8, 1.2, 1.4, 0.7]))


def _stored_flight() -> FlightData:
    data = np.load(GOLDEN.with_suffix(".npz"))
    return FlightData(data["t"], data["position"], data["quaternion"], data["rotor_speeds"],
                      "stored")


@pytest.mark.parametrize(("hidden", "start"), [
    (MotorLag(tau=0.04), MotorLag(tau=0.02)),
    (BodyDrag(k=0.05), BodyDrag(k=0.0)),
])
def test_hidden_effect_is_recovered_and_theta_improves(simulate_flight, hidden, start):
    """Given the right effect: its 95 % CI holds the truth; θ's worst error at most half."""
    cfg, flight = _hidden_flight(simulate_flight, hidden)
    without = estimate_with_effects(flight, _prior(cfg), [], FILTER_ONLY)
    with_effect = estimate_with_effects(flight, _prior(cfg), [start], FILTER_ONLY)
    (fitted,) = with_effect.effects
    lo, hi = fitted.ci95
    assert fitted.fitted and fitted.name == hidden.name
    assert lo[0] <= hidden.values[0] <= hi[0], (fitted.value, fitted.sigma)
    err_without = np.max(np.abs(without.final.value / cfg.theta - 1.0))
    err_with = np.max(np.abs(with_effect.final.value / cfg.theta - 1.0))
    assert err_with < 0.5 * err_without, (err_with, err_without)
    assert with_effect.log_likelihood > without.log_likelihood


def test_hidden_pose_delay_is_recovered_within_three_sigma(simulate_flight):
    """A 20 ms pose delay is found within 3σ (σ ≈ 0.4 ms) and removes c_D's bias."""
    cfg, flight = _hidden_flight(simulate_flight, PoseDelay(delay=0.02))
    without = estimate_with_effects(flight, _prior(cfg), [], FILTER_ONLY)
    result = estimate_with_effects(flight, _prior(cfg), [PoseDelay()], FILTER_ONLY)
    (fitted,) = result.effects
    assert abs(fitted.value[0] - 0.02) < 3.0 * fitted.sigma[0] < 0.003, fitted
    c_d_error = [abs(r.final.value[1] / cfg.theta[1] - 1.0) for r in (without, result)]
    assert c_d_error[1] < 0.5 * c_d_error[0], c_d_error


def test_zero_wrench_effect_equals_the_plain_model():
    """Body drag k = 0 held fixed: filter and refined θ and σ equal the recorded no-effect run."""
    golden = json.loads(GOLDEN.with_suffix(".json").read_text())
    cfg = load_vehicle("firefly")
    prior = cfg.with_parameters(cfg.theta * np.array([1.3, 0.6, 0.8, 1.2, 1.4, 0.7]))
    result = estimate_with_effects(_stored_flight(), prior, [BodyDrag(k=0.0), Wind()],
                                   fit_effects=False)
    np.testing.assert_allclose(result.filtered.value, golden["filtered"], rtol=1e-9)
    np.testing.assert_allclose(result.refined.value, golden["refined"], rtol=1e-9)
    np.testing.assert_allclose(result.refined.covariance, golden["refined_cov"], rtol=1e-7)
    assert [fe.fitted for fe in result.effects] == [False, False]
    assert np.all(np.isnan(result.effects[0].sigma))


def test_config_effects_are_used_by_estimate_parameters():
    """estimate_parameters takes config.effects: a fixed motor lag changes the filter's θ."""
    cfg = load_vehicle("firefly")
    flight = _stored_flight()
    plain = estimate_parameters(flight, cfg, FILTER_ONLY)
    lagged_cfg = replace(cfg, effects=(MotorLag(tau=0.03),))
    settings = EstimatorSettings(refine=False, fit_effects=False)
    lagged = estimate_parameters(flight, lagged_cfg, settings)
    assert [fe.effect for fe in lagged.effects] == [MotorLag(tau=0.03)]
    assert not np.allclose(lagged.filtered.value, plain.filtered.value, rtol=1e-4)


@pytest.mark.parametrize(("effects", "fragment"), [
    (["motor_lag"], "ModelEffect"),
    ([MotorLag(tau=0.02), MotorLag(tau=0.03)], "at most once"),
])
def test_bad_effect_lists_are_input_errors(effects, fragment):
    """A non-effect or a repeated effect is an InputError naming the problem."""
    cfg = load_vehicle("firefly")
    with pytest.raises(InputError, match=fragment):
        estimate_with_effects(_stored_flight(), cfg, effects)
