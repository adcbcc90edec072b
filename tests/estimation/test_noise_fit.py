"""Tests of the maximum-likelihood process-noise fit."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    flight_initial_state_sigma,
)
from mavsysid.estimation.filter.likelihood import (
    NOISE_SCALE_TOLERANCE,
    fit_noise_scale,
    maximise_log_scale,
    scaled_noise,
)
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


def _counted_runs(monkeypatch) -> list[float]:
    """The log-likelihood of every filter pass from now on."""
    passes: list[float] = []
    run = ParameterEKF.run

    def counted(self, *args, **kwargs):
        result = run(self, *args, **kwargs)
        passes.append(result.log_likelihood)
        return result

    monkeypatch.setattr(ParameterEKF, "run", counted)
    return passes


def test_fit_starts_from_the_run_at_the_configured_noise(monkeypatch, simulate_flight,
                                                         with_noise):
    """Given the pass at scale 1, the fit does not run it again and ends where it would
    without it; a few passes find the maximum of the likelihood to its tolerance."""
    base = load_vehicle("firefly")
    cfg = with_noise(base, 0.02 * base.mass, 0.02 * float(np.mean(base.parameters.J)))
    effect = ProcessNoise(4 * cfg.noise.force_density, 4 * cfg.noise.moment_density, seed=9)
    flight = simulate_flight(cfg, 3, duration=10.0, effects=[effect])
    prior = prior_from_config(cfg, EstimatorSettings())
    sigma = (cfg.noise.position_sigma, cfg.noise.attitude_sigma)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    unit = ParameterEKF(cfg, prior, sigma).run(flight, state_sigma)
    passes = _counted_runs(monkeypatch)
    fit = fit_noise_scale(flight, cfg, prior, sigma, state_sigma, unit_run=unit)
    assert unit.log_likelihood not in passes
    assert len(passes) <= 7
    again = fit_noise_scale(flight, cfg, prior, sigma, state_sigma)
    assert again.scale == fit.scale
    x = np.log10(fit.scale)
    around = [ParameterEKF(scaled_noise(cfg, 10.0 ** (x + d)), prior, sigma)
              .run(flight, state_sigma).log_likelihood for d in (-0.02, 0.02)]
    assert fit.run.log_likelihood >= max(around)


@pytest.mark.parametrize(("name", "ell", "expected"), [
    ("parabola in s^-1/2", lambda v: -(10 ** (-v / 2) - 10 ** (-0.59 / 2)) ** 2, 0.59),
    ("parabola in log s", lambda v: -(v - 1.4) ** 2, 1.4),
    ("quartic", lambda v: -((v + 1.7) ** 4) - 0.1 * (v + 1.7) ** 2, -1.7),
    ("rising to the lower edge", lambda v: -np.log1p(np.exp(3 * (v + 0.5))), -3.0),
    ("beyond the upper edge", lambda v: -(v - 5.0) ** 2, 3.0),
    ("overflow above 1", lambda v: -np.inf if v > 1.0 else -(v - 0.9) ** 2, 0.9),
])
def test_scale_search_finds_the_maximum_in_few_steps(name, ell, expected):
    """Over log10 s in [−3, 3] from 0, either first direction: within the tolerance (an
    edge exactly), in at most 12 evaluations, never outside the range."""
    for rising in (True, False):
        points: list[float] = []

        def f(v: float, points: list[float] = points) -> float:
            assert -3.0 <= v <= 3.0
            points.append(v)
            return float(ell(v))

        x = maximise_log_scale(f, 0.0, (-3.0, 3.0), rising)
        assert abs(x - expected) <= NOISE_SCALE_TOLERANCE, name
        assert len(points) == len(set(points)) <= 12, name
