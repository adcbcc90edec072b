"""Tests of the parameter EKF: filterpy API, scaling, and statistical consistency."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    flight_initial_state_sigma,
)
from mavsysid.estimation.results import prior_from_config
from mavsysid.flight.offline.effects import ProcessNoise
from mavsysid.vehicle.config import load_vehicle
from scipy.stats import chi2


def _filter(config, flight):
    prior = prior_from_config(config, EstimatorSettings())
    sigma = (config.noise.position_sigma, config.noise.attitude_sigma)
    return ParameterEKF(config, prior, sigma), flight_initial_state_sigma(flight, sigma)


def test_is_a_filterpy_extended_kalman_filter(simulate_flight):
    """ParameterEKF is a filterpy EKF and exposes x, P, Q, R, y, S, log_likelihood, mahalanobis."""
    cfg = load_vehicle("firefly")
    flight = simulate_flight(cfg, 0, duration=10.0)
    ekf, _ = _filter(cfg, flight)
    assert isinstance(ekf, ExtendedKalmanFilter)
    ekf.initialize(flight.position[0], flight.quaternion[0], np.zeros(3), np.zeros(3),
                   (0.01, 0.1, 0.01, 0.1))
    ekf.predict(flight.rotor_speeds[0], flight.t[1] - flight.t[0], flight.rotor_speeds[1])
    assert ekf.P.shape == (18, 18) and ekf.Q.shape == (18, 18) and ekf.x.shape == (19,)
    ekf.update(np.concatenate([flight.position[1], flight.quaternion[1]]))
    assert ekf.y.shape == (6,) and ekf.S.shape == (6, 6)
    assert np.isfinite(ekf.log_likelihood)
    assert ekf.mahalanobis == pytest.approx(np.sqrt(ekf.y @ np.linalg.solve(ekf.S, ekf.y)))


def test_step_by_step_equals_the_compiled_run(simulate_flight):
    """predict()/update() per sample reach the same x and P as run() (shared kernels)."""
    cfg = load_vehicle("firefly")
    flight = simulate_flight(cfg, 0, duration=10.0).time_slice(0.0, 3.0)
    a, state_sigma = _filter(cfg, flight)
    run = a.run(flight, state_sigma)
    b, _ = _filter(cfg, flight)
    t, q = flight.t, flight.quaternion
    b.initialize(flight.position[0], q[0], run.states[0][3:6], run.states[0][10:13], state_sigma)
    for k in range(1, len(flight)):
        b.predict(flight.rotor_speeds[k - 1], t[k] - t[k - 1], flight.rotor_speeds[k])
        b.update(np.concatenate([flight.position[k], q[k]]))
    np.testing.assert_allclose(b.x, a.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(b.P, a.P, rtol=1e-8, atol=1e-20)


@pytest.mark.parametrize("name", ["firefly", "micro_quad"])
def test_parameter_covariance_is_well_conditioned_at_any_scale(simulate_flight, name):
    """In scaled units the θ block of P has a moderate condition number for 30 g and 1.6 kg."""
    cfg = load_vehicle(name)
    flight = simulate_flight(cfg, 0, duration=10.0)
    ekf, state_sigma = _filter(cfg, flight)
    ekf.run(flight, state_sigma)
    assert np.linalg.cond(ekf.P[12:, 12:]) < 1e6
    assert np.all(np.isfinite(ekf.theta_covariance))


@pytest.mark.slow
def test_filter_is_consistent_when_the_truth_has_its_process_noise(
    simulate_flight, prior_config, with_noise
):
    """With the simulator injecting the filter's Q: NIS per flight and θ ANEES in 95 % χ² bands.

    Logged at the controller's 500 Hz: at 100 Hz the controller's reaction to noise inside
    a sample interval is invisible to the filter, whose NIS then runs about 1.5 % low.
    """
    base = load_vehicle("firefly")
    truth_cfg = with_noise(base, 0.02 * base.mass, 0.02 * float(np.mean(base.parameters.J)))
    seeds = range(10)
    eps = []
    for seed in seeds:
        effect = ProcessNoise(truth_cfg.noise.force_density, truth_cfg.noise.moment_density,
                              seed=500 + seed)
        flight = simulate_flight(truth_cfg, seed, effects=[effect], log_rate=500.0)
        ekf, state_sigma = _filter(prior_config(truth_cfg, seed), flight)
        run = ekf.run(flight, state_sigma)
        nis = run.history.nis[1:]
        n = nis.size
        assert chi2.ppf(0.025, 6 * n) / n < nis.mean() < chi2.ppf(0.975, 6 * n) / n, seed
        e = run.estimate.value - truth_cfg.theta
        eps.append(e @ np.linalg.solve(run.estimate.covariance, e))
    m = len(eps)
    anees = float(np.mean(eps))
    assert chi2.ppf(0.025, 6 * m) / m < anees < chi2.ppf(0.975, 6 * m) / m, anees


def _with_gap(flight, t0, t1):
    """The flight without the samples t0 < t < t1, as two segments."""
    keep = ~((flight.t > t0) & (flight.t < t1))
    cut = flight.time_slice(-np.inf, np.inf)
    second = int(np.searchsorted(flight.t[keep], t1))
    return replace(cut, t=cut.t[keep], position=cut.position[keep],
                   quaternion=cut.quaternion[keep], rotor_speeds=cut.rotor_speeds[keep],
                   segment_starts=(0, second))


def test_segments_restart_the_states_and_carry_theta(simulate_flight):
    """After a gap the states restart from the measurement (not predicted across the gap),
    while θ and its covariance carry on: the second segment ends better informed than it
    does filtered alone."""
    cfg = load_vehicle("firefly")
    flight = _with_gap(simulate_flight(cfg, 3, duration=12.0), 5.0, 5.5)
    a = flight.segment_starts[1]
    ekf, state_sigma = _filter(cfg, flight)
    run = ekf.run(flight, state_sigma)
    np.testing.assert_array_equal(run.history.position[a], flight.position[a])
    assert np.isnan(run.history.nis[a]) and np.isfinite(run.history.nis[a + 1:]).all()
    alone_ekf, _ = _filter(cfg, flight)
    alone = alone_ekf.run(flight.segment(1), state_sigma)
    assert (run.estimate.sigma < alone.estimate.sigma).all()
    bridged_ekf, _ = _filter(cfg, flight)
    bridged = bridged_ekf.run(replace(flight, segment_starts=(0,)), state_sigma)
    assert not np.array_equal(bridged.history.position[a], flight.position[a])
