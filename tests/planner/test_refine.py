"""Tests of the refinement of the search's best flight (planner/refine.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from planner.feasibility import check_segment
from planner.refine import PathRefiner, RefinablePath, StopChoice
from planner.results import PlannerSettings
from planner.rrbt import plan
from planner.segments import VertexState, connect_fixed
from vehicle.config import load_vehicle
from vehicle.errors import InputError


@pytest.fixture(scope="module")
def plans():
    """The same search without and with refinement."""
    cfg = load_vehicle("firefly")
    settings = PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=120, seed=2,
                               refine_steps=0)
    return cfg, settings, plan(cfg, settings), plan(cfg, replace(settings, refine_steps=400))


def test_refinement_lowers_the_predicted_dopt(plans):
    """The refined flight's D-opt, re-predicted at the measurement rate, beats the search's."""
    _, _, searched, refined = plans
    assert refined.stats.refine_steps == 400 and refined.stats.refine_accepted > 0
    assert refined.predicted_dopt < 0.97 * searched.predicted_dopt


def test_refined_flight_is_feasible_continuous_and_within_budget(plans):
    """Every refined segment passes the feasibility check; joints are C⁴ (yaw C²)."""
    cfg, settings, _, refined = plans
    traj = refined.trajectory
    box = np.asarray(settings.box)
    assert traj.duration <= settings.budget + 1e-9
    starts = np.concatenate([traj.segment_starts, [traj.duration]])
    for k in range(traj.durations.size):
        segment = connect_fixed(_state(traj, starts[k], 1e-9), _state(traj, starts[k + 1], -1e-9),
                                float(traj.durations[k]))
        assert check_segment(segment, cfg, box).feasible
    for t in starts[1:-1]:
        left = traj.flat_outputs(np.array([t - 1e-9]))
        right = traj.flat_outputs(np.array([t + 1e-9]))
        for name, tol in (("position", 1e-6), ("velocity", 1e-5), ("acceleration", 1e-4),
                          ("jerk", 1e-3), ("yaw", 1e-6), ("yaw_rate", 1e-5)):
            np.testing.assert_allclose(getattr(left, name), getattr(right, name), atol=tol)


def _state(traj, t: float, nudge: float) -> VertexState:
    f = traj.flat_outputs(np.array([t + nudge]))
    position = np.stack([f.position[0], f.velocity[0], f.acceleration[0], f.jerk[0], f.snap[0]])
    return VertexState(position, np.array([f.yaw[0], f.yaw_rate[0], f.yaw_acceleration[0]]))


def test_refiner_keeps_the_flight_when_nothing_is_feasible():
    """With every candidate segment infeasible, no step is accepted and the flight is kept."""
    start = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    end = VertexState.hover(np.array([1.0, 0.0, 1.5]), 0.0)
    segment = connect_fixed(start, end, 2.0)
    calls = []
    path = RefinablePath((start, end), (segment,), (None,), StopChoice(None, None), 1.0)
    refiner = PathRefiner(path, feasible=lambda s: False, transfer_of=calls.append,
                          stop_at=lambda v: StopChoice(None, None), dopt_of=lambda t: 0.0,
                          box=np.array([-2.0, -2.0, 0.5, 2.0, 2.0, 2.5]), budget=10.0,
                          rng=np.random.default_rng(0))
    assert not any(refiner.step() for _ in range(50))
    assert refiner.path is path and not calls


def test_refiner_respects_the_budget():
    """A candidate that would make the flight longer than the budget is never kept."""
    start = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    end = VertexState.hover(np.array([1.0, 0.0, 1.5]), 0.0)
    path = RefinablePath((start, end), (connect_fixed(start, end, 2.0),), (None,),
                         StopChoice(None, None), 1.0)
    # A D-opt that rewards longer flights: only the budget holds the refiner back.
    refiner = PathRefiner(path, feasible=lambda s: True, transfer_of=lambda s: s.duration,
                          stop_at=lambda v: StopChoice(None, None),
                          dopt_of=lambda t: -float(sum(x for x in t if x is not None)),
                          box=np.array([-2.0, -2.0, 0.5, 2.0, 2.0, 2.5]), budget=2.5,
                          rng=np.random.default_rng(1))
    for _ in range(300):
        refiner.step()
    assert refiner.accepted > 0 and 2.0 < refiner.path.duration <= 2.5


@pytest.mark.parametrize("change", [{"refine_share": 1.0}, {"refine_share": -0.1},
                                    {"refine_steps": -1}])
def test_bad_refinement_settings_are_refused(change):
    """A refinement share outside [0, 1) or negative steps is an input error, not a crash."""
    settings = replace(PlannerSettings(max_samples=5, planning_time=np.inf), **change)
    with pytest.raises(InputError, match="refinement"):
        plan(load_vehicle("firefly"), settings)
