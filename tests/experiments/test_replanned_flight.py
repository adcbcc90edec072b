"""Tests of offline re-planning: the posterior as the rest's prior, the join, the whole loop."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation import estimate
from mavsysid.estimation.readers import load_flight
from mavsysid.experiments.experiment import draw_prior
from mavsysid.experiments.replanned_flight import (
    concatenate,
    end_hover,
    opening_settings,
    replan_flight,
)
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.pipeline.replanned_stream import relative_covariance
from mavsysid.planner.plan_request import check_request, rotor_clearance
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import InputError

FLAT = ("position", "velocity", "acceleration", "jerk", "snap", "yaw", "yaw_rate",
        "yaw_acceleration")


def _hover_to_hover(rng: np.random.Generator, start: np.ndarray, start_yaw: float,
                    pieces: int) -> PiecewisePolynomial:
    """A random flight from hover at ``start`` to hover elsewhere, moving in between."""
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 2.0, pieces))])
    pos = rng.normal(0.0, 0.5, (pieces + 1, 5, 3))
    yaw = rng.normal(0.0, 0.5, (pieces + 1, 3))
    pos[0] = 0.0
    pos[0, 0] = start
    yaw[0] = [start_yaw, 0.0, 0.0]
    pos[-1, 1:] = 0.0
    yaw[-1, 1:] = 0.0
    return PiecewisePolynomial.from_waypoints(times, pos, yaw)


def test_concatenate_flies_the_second_right_after_the_first():
    rng = np.random.default_rng(13)
    first = _hover_to_hover(rng, np.array([0.1, -0.2, 1.5]), 0.4, 3)
    x, y, z, yaw = end_hover(first)
    second = _hover_to_hover(rng, np.array([x, y, z]), yaw, 4)
    # A different coefficient count on the second (padded with zero high powers).
    second = PiecewisePolynomial(second.durations,
                                 np.pad(second.position_coeffs, ((0, 0), (0, 0), (0, 2))),
                                 second.yaw_coeffs)
    joined = concatenate(first, second)
    assert joined.duration == pytest.approx(first.duration + second.duration)
    t1 = np.linspace(0.0, first.duration, 37)
    t2 = np.linspace(0.0, second.duration, 41)
    for name in FLAT:
        np.testing.assert_allclose(getattr(joined.flat_outputs(t1), name),
                                   getattr(first.flat_outputs(t1), name), atol=1e-9)
        np.testing.assert_allclose(getattr(joined.flat_outputs(first.duration + t2), name),
                                   getattr(second.flat_outputs(t2), name), atol=1e-9)


def test_concatenate_refuses_a_jump():
    rng = np.random.default_rng(14)
    first = _hover_to_hover(rng, np.array([0.0, 0.0, 1.5]), 0.0, 2)
    x, y, z, yaw = end_hover(first)
    for start, start_yaw in (([x + 0.01, y, z], yaw), ([x, y, z], yaw + 0.01)):
        second = _hover_to_hover(rng, np.array(start), start_yaw, 2)
        with pytest.raises(ValueError, match="do not join"):
            concatenate(first, second)


def test_end_hover_is_where_the_flight_stops():
    rng = np.random.default_rng(15)
    flight = _hover_to_hover(rng, np.array([0.3, 0.2, 1.1]), -0.7, 3)
    end = flight.flat_outputs(np.array([flight.duration]))
    assert end_hover(flight) == pytest.approx((*end.position[0], end.yaw[0]), abs=1e-12)


def test_an_opening_end_anywhere_in_its_box_is_a_valid_start():
    config = load_vehicle("firefly")
    settings = PlannerSettings(box=(-1.0, -2.0, 0.5, 2.0, 1.0, 2.5))
    inner = np.asarray(opening_settings(settings, config, 4.0).box)
    assert opening_settings(settings, config, 4.0).budget == 4.0
    for corner in (inner[:3], inner[3:], np.array([inner[0], inner[4], inner[2]])):
        check_request(config, replace(settings, start=(*corner, 0.3)))  # no InputError
    # Just outside the inset box the start check refuses: the inset is not wider than needed.
    outside = inner[:3] - (inner[:3] - np.asarray(settings.box[:3])) * 0.9
    with pytest.raises(InputError, match="--start"):
        check_request(config, replace(settings, start=(*outside, 0.0)))
    assert inner[0] - settings.box[0] == pytest.approx(rotor_clearance(config) + 0.01)


@pytest.mark.slow
def test_replanned_flight_starts_the_rest_from_the_opening_posterior(tmp_path):
    truth = load_vehicle("firefly")
    prior = truth.with_parameters(draw_prior(truth, 2))
    settings = PlannerSettings(budget=20.0, planning_time=5.0, seed=2)
    sim = Simulator(truth, true_theta=truth.theta, settings=SimulationSettings(seed=2))
    flight = replan_flight(prior, settings, sim, tmp_path / "opening", opening_budget=6.0)
    opening, rest = flight.opening.trajectory, flight.rest.trajectory
    assert opening.duration <= 6.0 + 1e-9
    assert flight.trajectory.duration == pytest.approx(opening.duration + rest.duration)
    assert flight.trajectory.duration <= settings.budget + 1e-9
    assert flight.rest_settings.start == pytest.approx(end_hover(opening))
    assert flight.rest_settings.budget == pytest.approx(settings.budget - opening.duration)
    np.testing.assert_allclose(flight.rest_config.theta, flight.posterior.value)
    np.testing.assert_allclose(flight.rest_settings.theta_covariance,
                               relative_covariance(flight.posterior), rtol=1e-12)
    # The opening taught something: every σ below the prior's ±50 %.
    assert np.all(flight.posterior.sigma < 0.5 * prior.theta)
    # The posterior is what `estimate` (and a stream's continuation) reports on the opening.
    assert flight.refusal is None
    again = estimate(load_flight(tmp_path / "opening" / "pose.csv", prior), prior).final
    np.testing.assert_allclose(flight.posterior.value, again.value, rtol=1e-9)
    np.testing.assert_allclose(flight.posterior.covariance, again.covariance, rtol=1e-9)
