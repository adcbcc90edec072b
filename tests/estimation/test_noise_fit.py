"""Tests of the maximum-likelihood process-noise fit."""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    flight_initial_state_sigma,
)
from mavsysid.estimation.filter.likelihood import fit_noise_scale
from mavsysid.estimation.results import prior_from_config
from mavsysid.flight.offline.effects import ProcessNoise
from mavsysid.vehicle.config import load_vehicle


def test_fit_recovers_the_injected_noise_level(simulate_flight, prior_config, with_noise):
    """Noise injected at 4× the configured densities is found within a factor 1.6."""
    base = load_vehicle("firefly")
    cfg = with_noise(base, 0.02 * base.mass, 0.02 * float(np.mean(base.parameters.J)))
    effect = ProcessNoise(4 * cfg.noise.force_density, 4 * cfg.noise.moment_density, seed=9)
    flight = simulate_flight(cfg, 3, effects=[effect])
    prior_cfg = prior_config(cfg, 3)
    prior = prior_from_config(prior_cfg, EstimatorSettings())
    sigma = (cfg.noise.position_sigma, cfg.noise.attitude_sigma)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    fit = fit_noise_scale(flight, prior_cfg, prior, sigma, state_sigma)
    assert 4 / 1.6 < fit.scale < 4 * 1.6
    assert not fit.at_bound


def test_noise_free_truth_drives_the_scale_down(simulate_flight):
    """A flight without process noise fits a scale well below the configured one."""
    cfg = load_vehicle("firefly")
    flight = simulate_flight(cfg, 2, duration=10.0)
    prior = prior_from_config(cfg, EstimatorSettings())
    sigma = (cfg.noise.position_sigma, cfg.noise.attitude_sigma)
    fit = fit_noise_scale(flight, cfg, prior, sigma, flight_initial_state_sigma(flight, sigma))
    assert fit.scale < 0.1
