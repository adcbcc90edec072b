"""Tests of the baselines: the practitioner's scaled excitation, the oracle, the ablation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.experiments import baselines
from mavsysid.experiments.baselines import (
    BASELINES,
    baseline_trajectory,
    excitation_violation,
    practitioner_excitation,
)
from mavsysid.planner.feasibility import CONSTRAINTS, check_segment
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.segments import VertexState, connect_fixed
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import GRAVITY, load_vehicle
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.trajectory import PiecewisePolynomial

SETTINGS = PlannerSettings(budget=20.0)


@pytest.fixture(scope="module")
def prior():
    """A Firefly whose θ is a seeded ±50 % draw, as the planner and practitioner know it."""
    truth = load_vehicle("firefly")
    rng = np.random.default_rng(7)
    return truth.with_parameters(truth.theta * (1.0 + rng.uniform(-0.5, 0.5, 6)))


def _dense_peaks(trajectory: PiecewisePolynomial, config) -> dict[str, float]:
    """Each limit's use (peak / limit, ≤ 1 inside) sampled every 2 ms by flatness alone."""
    t = np.append(np.arange(0.0, trajectory.duration, 2e-3), trajectory.duration)
    flat = trajectory.flat_outputs(t)
    state = flat_to_state(flat, config)
    lim = config.limits
    accel = np.linalg.norm(flat.acceleration + [0.0, 0.0, GRAVITY], axis=1) / GRAVITY
    box = np.asarray(SETTINGS.box)
    n2 = state.rotor_speeds_squared
    return {
        "box": float(np.max(np.maximum(box[:3] - flat.position, flat.position - box[3:]))),
        "thrust_max": float(accel.max() / lim.thrust_max_ratio),
        "thrust_min": float(lim.thrust_min_ratio / accel.min()),
        "speed": float(np.linalg.norm(flat.velocity, axis=1).max() / lim.speed_max),
        "yaw_acceleration": float(np.abs(flat.yaw_acceleration).max()
                                  / lim.yaw_acceleration_max),
        "body_rate": float(np.linalg.norm(state.body_rates, axis=1).max() / lim.body_rate_max),
        "rotor_max": float(n2.max() / lim.rotor_speed_max**2),
        "rotor_min": float(lim.rotor_speed_min**2 - n2.min()),
    }


def test_scaled_excitation_respects_every_limit_at_the_prior(prior):
    scaled = practitioner_excitation(prior, SETTINGS)
    assert scaled.trajectory.duration == pytest.approx(SETTINGS.budget)
    peaks = _dense_peaks(scaled.trajectory, prior)
    tol = 1e-6
    assert peaks["box"] <= tol
    for name in ("thrust_max", "thrust_min", "speed", "yaw_acceleration", "body_rate",
                 "rotor_max"):
        assert peaks[name] <= 1.0 + tol, (name, peaks)
    assert peaks["rotor_min"] <= tol
    # Scaled to the limits, not merely inside: some limit is nearly used up, and the
    # bisection names the one a faster figure breaks.
    assert max(peaks[n] for n in ("speed", "yaw_acceleration", "body_rate", "rotor_max",
                                  "thrust_max")) > 0.9
    assert scaled.binding in CONSTRAINTS
    assert excitation_violation(scaled.trajectory, prior, SETTINGS) == ""


def test_excitation_is_scaled_at_the_prior_it_is_given(prior):
    """Rotor limits are the prior's: a vehicle with a quarter of the yaw moment
    coefficient gets a slower (or equal) figure, never a faster one."""
    weak = prior.with_parameters(prior.theta * [1.0, 1.0, 0.25, 1.0, 1.0, 1.0])
    slow = practitioner_excitation(weak, SETTINGS)
    assert slow.binding == "rotor_speed"
    assert slow.scale <= practitioner_excitation(prior, SETTINGS).scale


def test_oracle_plans_with_the_truth_and_the_others_with_the_prior(prior, monkeypatch):
    truth = load_vehicle("firefly")
    seen = []

    class Planned:
        trajectory = "planned"

    def fake_plan(config, settings):
        seen.append((config.theta.copy(), settings))
        return Planned()

    monkeypatch.setattr(baselines, "plan", fake_plan)
    monkeypatch.setattr(baselines, "plan_random", fake_plan)
    for kind in ("oracle", "paper_constraints", "random"):
        assert baseline_trajectory(kind, prior, truth, SETTINGS) == "planned"
    (oracle_theta, oracle_settings), (paper_theta, paper_settings), (rand_theta, _) = seen
    np.testing.assert_array_equal(oracle_theta, truth.theta)
    assert oracle_settings.rotor_check
    np.testing.assert_array_equal(paper_theta, prior.theta)
    assert not paper_settings.rotor_check
    np.testing.assert_array_equal(rand_theta, prior.theta)
    with pytest.raises(ValueError, match="unknown baseline"):
        baseline_trajectory("chirp", prior, truth, SETTINGS)
    assert set(BASELINES) == {"random", "practitioner", "oracle", "paper_constraints"}


def _fast_yaw_turn():
    """A hover-to-hover yaw turn the Firefly's rotors cannot fly, all else within limits."""
    p = np.array([0.0, 0.0, 1.5])
    return connect_fixed(VertexState.hover(p, 0.0), VertexState.hover(p, 1.5), 1.3)


def test_ablation_switch_removes_only_the_rotor_check():
    cfg = load_vehicle("firefly")
    box = np.asarray(SETTINGS.box)
    segment = _fast_yaw_turn()
    assert check_segment(segment, cfg, box).reason == "rotor_speed"
    assert check_segment(segment, cfg, box, rotor_check=False).feasible
    # Other limits still hold without the rotor check: the same turn, faster.
    p = np.array([0.0, 0.0, 1.5])
    turn = connect_fixed(VertexState.hover(p, 0.0), VertexState.hover(p, 1.5), 0.8)
    assert check_segment(turn, cfg, box, rotor_check=False).reason == "yaw_acceleration"
    # The planner's own check follows the settings' switch.
    for switch in (True, False):
        search = GraphSearch(cfg, replace(SETTINGS, rotor_check=switch), "dopt", None)
        assert search.feasible(segment) is not switch
