"""Tests of the data-efficiency endpoint."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.experiments.data_efficiency import (
    belief_history,
    first_crossing,
    seconds_to_dopt,
    seconds_to_relative_sigma,
)
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

SETTINGS = PlannerSettings(measurement_rate=50.0)


def test_first_crossing_interpolates_in_log():
    t = np.arange(5.0)
    values = np.exp(-t)  # log-linear: the crossing of e^-2.5 is at 2.5 exactly
    assert first_crossing(t, values, np.exp(-2.5)) == pytest.approx(2.5)
    assert first_crossing(t, values, 2.0) == 0.0
    assert np.isnan(first_crossing(t, values, np.exp(-5.0)))


def test_relative_sigma_waits_for_the_slowest_parameter():
    rng = np.random.default_rng(3)
    theta = rng.uniform(0.5, 2.0, 6) * [-1, 1, 1, 1, 1, 1]
    t = np.linspace(0.0, 20.0, 201)
    rates = rng.uniform(0.3, 1.0, 6)
    sigma = np.abs(theta) * 0.5 * np.exp(-np.outer(t, rates))
    expected = np.log(50.0) / rates.min()  # 0.5 e^{-r t} = 0.01
    assert seconds_to_relative_sigma(t, sigma, theta) == pytest.approx(expected, rel=1e-9)
    assert np.isnan(seconds_to_relative_sigma(t[:50], sigma[:50], theta))


@pytest.fixture(scope="module")
def flight():
    return load_vehicle("firefly"), excitation_trajectory(ExcitationSpec(duration=10.0))


def test_belief_history_repeats_the_flight_from_where_it_ended(flight):
    cfg, trajectory = flight
    one = belief_history(cfg, trajectory, SETTINGS, passes=1)
    two = belief_history(cfg, trajectory, SETTINGS, passes=2)
    assert one.t[-1] == pytest.approx(trajectory.duration)
    assert two.t[-1] == pytest.approx(2.0 * trajectory.duration)
    np.testing.assert_allclose(two.dopt[:one.dopt.size], one.dopt, rtol=1e-12)
    assert np.all(np.diff(two.dopt) <= 1e-12 * two.dopt[:-1])
    assert two.dopt[-1] < one.dopt[-1]


def test_seconds_to_dopt_finds_the_flights_own_end(flight):
    cfg, trajectory = flight
    history = belief_history(cfg, trajectory, SETTINGS, passes=3)
    steps = history.t.size - 1
    for k in (1, 3):
        target = history.dopt[k * steps // 3]
        seconds = seconds_to_dopt(cfg, trajectory, SETTINGS, target, max_passes=4)
        assert seconds == pytest.approx(k * trajectory.duration, abs=2.0 / 50.0)
    assert np.isnan(seconds_to_dopt(cfg, trajectory, SETTINGS, history.dopt[-1] * 1e-3,
                                    max_passes=2))
