"""The planner's predicted σ against what the estimator reaches on the flown plan."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import EstimatorSettings, estimate_parameters
from mavsysid.estimation.readers import load_flight
from mavsysid.flight.offline.effects import ProcessNoise
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.flatness import flat_to_state


@pytest.mark.parametrize("seed", [0, 1])
def test_predicted_sigma_matches_the_estimator(tmp_path, seed):
    """With an exact model, the predicted final σ is within 10 % of the filter's on the flight.

    The world carries the process noise the filter assumes, so that σ means something.
    (With priors ±50 % off, the planner linearises at the wrong θ and the coupled
    parameters c_D, c_M, j_z can be off by ~40 %: bench/planner_vs_random.py reports it.)
    """
    cfg = load_vehicle("firefly")
    result = plan(cfg, PlannerSettings(budget=20.0, planning_time=np.inf, max_samples=200,
                                       seed=seed, refine_steps=300))
    noise = ProcessNoise(cfg.noise.force_density, cfg.noise.moment_density, seed=seed)
    Simulator(cfg, settings=SimulationSettings(seed=seed), effects=[noise]).run(
        result.trajectory, tmp_path / "f")
    est = estimate_parameters(load_flight(tmp_path / "f" / "pose.csv", cfg), cfg,
                              EstimatorSettings(refine=False))
    ratio = result.predicted_sigma[-1] / est.filtered.sigma
    assert np.all(np.abs(ratio - 1.0) < 0.10), ratio
    assert result.trajectory.duration <= 20.0 + 1e-9


def test_same_seed_and_sample_budget_give_the_same_plan():
    """With a sample budget the plan depends only on the seed, not on timing."""
    cfg = load_vehicle("firefly")
    settings = PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=150, seed=3,
                               refine_steps=300)
    a, b = plan(cfg, settings), plan(cfg, replace(settings))
    np.testing.assert_array_equal(a.trajectory.durations, b.trajectory.durations)
    np.testing.assert_array_equal(a.trajectory.position_coeffs, b.trajectory.position_coeffs)
    assert a.predicted_dopt == b.predicted_dopt


def test_plan_starts_and_ends_in_hover_inside_the_budget():
    """The flight starts and ends at rest within the budget; the best D-opt only improves."""
    cfg = load_vehicle("firefly")
    settings = PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=150, seed=5,
                               refine_steps=300)
    result = plan(cfg, settings)
    traj = result.trajectory
    ends = traj.flat_outputs(np.array([0.0, traj.duration]))
    np.testing.assert_allclose(ends.position[0], settings.start_pose[:3], atol=1e-9)
    for arr in (ends.velocity, ends.acceleration, ends.jerk):
        np.testing.assert_allclose(arr, 0.0, atol=1e-7)
    assert traj.duration <= settings.budget + 1e-9
    history = result.stats.best_history
    assert history.shape[0] >= 1 and np.all(np.diff(history[:, 1]) < 0.0)


def test_rotor_headroom_keeps_the_whole_flight_inside_the_shrunk_rotor_range():
    """A plan with headroom h keeps n² in [h, 1 − h] of the range; without, it uses more."""
    cfg = load_vehicle("firefly")
    settings = PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=150, seed=2,
                               refine_steps=300)
    span = cfg.limits.rotor_speed_max**2
    used = {}
    for headroom in (0.0, 0.15):
        traj = plan(cfg, replace(settings, rotor_headroom=headroom)).trajectory
        t = np.append(np.arange(0.0, traj.duration, 1e-3), traj.duration)
        n2 = flat_to_state(traj.flat_outputs(t), cfg).rotor_speeds_squared / span
        used[headroom] = (n2.min(), n2.max())
    assert used[0.15][0] >= 0.15 and used[0.15][1] <= 0.85
    assert used[0.0][0] < 0.15 or used[0.0][1] > 0.85, used
