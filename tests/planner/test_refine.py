"""Tests of the refinement of the search's best flight (planner/refine.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.planner.belief import apply_transfer, identity_transfer
from mavsysid.planner.best_flight import best_path
from mavsysid.planner.feasibility import check_segment
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.refine import (
    FlightPricing,
    PathRefiner,
    RefinablePath,
    StopChoice,
    split_path,
)
from mavsysid.planner.rrbt import plan
from mavsysid.planner.segments import VertexState, connect_fixed, to_piecewise
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError
from tests.support.refined_paths import assert_consistent_flight


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
    # Every segment but the final stop within the segment time limit.
    assert traj.durations[:-1].max() <= cfg.limits.segment_time_max + 1e-12
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


def _scalar_pricing(calls: list | None = None) -> FlightPricing:
    """A stand-in belief: a number that drops by each segment's duration (longer is better)."""
    def propagate(sigma, segments):
        if calls is not None:
            calls.append(segments)
        return sigma - sum(s.duration for s in segments)
    return FlightPricing(sigma0=0.0, propagate=propagate, transfer=lambda s: s.duration,
                         apply=lambda sigma, t: sigma - t, dopt=lambda sigma: sigma, identity=0.0)


def _two_vertex_path(stop_duration: float = 0.0) -> RefinablePath:
    start = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    end = VertexState.hover(np.array([1.0, 0.0, 1.5]), 0.0)
    return RefinablePath((start, end), (connect_fixed(start, end, 2.0),), (2.0,),
                         StopChoice(None, 0.0), -2.0)


def test_refiner_keeps_the_flight_when_nothing_is_feasible():
    """With every candidate segment infeasible, no step is accepted and nothing is priced."""
    calls = []
    path = _two_vertex_path()
    refiner = PathRefiner(path, feasible=lambda s: False,
                          stop_at=lambda v: StopChoice(None, None), pricing=_scalar_pricing(calls),
                          box=np.array([-2.0, -2.0, 0.5, 2.0, 2.0, 2.5]), budget=10.0,
                          rng=np.random.default_rng(0))
    assert not any(refiner.step() for _ in range(50))
    assert refiner.path is path and not calls


def test_refiner_respects_the_budget():
    """A candidate that would make the flight longer than the budget is never kept."""
    # A D-opt that rewards longer flights: only the budget holds the refiner back.
    refiner = PathRefiner(_two_vertex_path(), feasible=lambda s: True,
                          stop_at=lambda v: StopChoice(None, None), pricing=_scalar_pricing(),
                          box=np.array([-2.0, -2.0, 0.5, 2.0, 2.0, 2.5]), budget=2.5,
                          rng=np.random.default_rng(1))
    for _ in range(300):
        refiner.step()
    assert refiner.accepted > 0 and 2.0 < refiner.path.duration <= 2.5
    assert refiner.path.dopt == pytest.approx(-refiner.path.duration)


@pytest.mark.parametrize(("change", "fragment"), [
    ({"refine_share": 1.0}, "^refinement: share 1 "),
    ({"refine_share": -0.1}, "^refinement: share -0.1 "),
    ({"refine_steps": -1}, "^--refine-steps -1: "),
    ({"refine_split": 0}, "^refinement: .* split 0 "),
])
def test_bad_refinement_settings_are_refused(change, fragment):
    """A refinement share outside [0, 1), negative steps or a split < 1 is an input error,
    not a crash."""
    settings = replace(PlannerSettings(max_samples=5, planning_time=np.inf), **change)
    with pytest.raises(InputError, match=fragment):
        plan(load_vehicle("firefly"), settings)


@pytest.fixture(scope="module")
def searched():
    """A finished search (no refinement yet) and its best flight."""
    cfg = load_vehicle("firefly")
    settings = PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=150, seed=4,
                               refine_steps=300)
    search = GraphSearch(cfg, settings, "dopt", None)
    search.run()
    return search, best_path(search)


def test_best_path_is_the_searched_flight_with_continuous_yaw(searched):
    """The path's vertices are its segments' own end states (yaw shifted by whole turns at
    most), so re-solving a segment between them gives the same polynomial."""
    search, path = searched
    assert path.dopt == pytest.approx(search.history[-1][1], rel=1e-9)
    for j, segment in enumerate(path.segments):
        start, end = segment.start_state(), segment.end_state()
        np.testing.assert_allclose(start.yaw, path.vertices[j].yaw, atol=1e-9)
        np.testing.assert_allclose(end.yaw, path.vertices[j + 1].yaw, atol=1e-6)
        np.testing.assert_allclose(end.position, path.vertices[j + 1].position, atol=1e-6)
        again = connect_fixed(path.vertices[j], path.vertices[j + 1], segment.duration)
        np.testing.assert_allclose(again.yaw_coeffs, segment.yaw_coeffs, rtol=1e-6, atol=1e-6)
    if path.stop.segment is not None:
        np.testing.assert_allclose(path.stop.segment.start_state().yaw, path.vertices[-1].yaw,
                                   atol=1e-6)


def test_split_path_keeps_the_flight_and_its_dopt(searched):
    """Cutting every segment in three keeps the flown polynomial and the predicted D-opt."""
    search, path = searched
    split = split_path(path, 3, search.feasible, search.transfer_of)
    assert len(split.segments) == 3 * len(path.segments)
    a, b = to_piecewise(path.segments), to_piecewise(split.segments)
    assert b.duration == pytest.approx(a.duration, rel=1e-12)
    t = np.linspace(0.0, a.duration, 777)
    fa, fb = a.flat_outputs(t), b.flat_outputs(t)
    np.testing.assert_allclose(fb.position, fa.position, atol=1e-9)
    np.testing.assert_allclose(fb.yaw, fa.yaw, atol=1e-9)
    # Snap jumps at the original knots; a sample on one may fall on either side of it.
    knots = np.cumsum(a.durations)
    smooth = np.min(np.abs(t[:, None] - knots[None, :]), axis=1) > 1e-9
    np.testing.assert_allclose(fb.snap[smooth], fa.snap[smooth], rtol=1e-6, atol=1e-6)
    assert all(search.feasible(s) for s in split.segments)
    dopt = search.flight_dopt([*split.transfers, split.stop.transfer])
    assert dopt == pytest.approx(path.dopt, rel=1e-3)


def test_incremental_pricing_matches_pricing_from_scratch(searched):
    """After many kept changes, the refiner's cached D-opt equals the flight's D-opt
    re-propagated from the start with fresh transfers; it never got worse; all feasible."""
    search, path = searched
    refiner = PathRefiner(path, search.feasible, lambda v: search.stop_at(v, False),
                          FlightPricing(search.sigma0, search.propagate_segments,
                                        search.kept_transfer, apply_transfer, search.dopt,
                                        identity_transfer()),
                          search.box, search.settings.budget, np.random.default_rng(3))
    history = [refiner.path.dopt]
    for _ in range(300):
        refiner.step()
        history.append(refiner.path.dopt)
    final = refiner.path
    assert refiner.accepted > 5
    assert np.all(np.diff(history) <= 0.0) and final.dopt < path.dopt
    assert_consistent_flight(search, final)


def _shorter_is_better() -> FlightPricing:
    """A stand-in belief that rewards shorter flights: only a floor holds the refiner back."""
    return FlightPricing(sigma0=0.0,
                         propagate=lambda sigma, segs: sigma + sum(s.duration for s in segs),
                         transfer=lambda s: s.duration, apply=lambda sigma, t: sigma + t,
                         dopt=lambda sigma: sigma, identity=0.0)


@pytest.mark.parametrize("floor", [1.8, 2.5])
def test_refiner_keeps_the_shortest_flight(floor):
    """No kept flight is shorter than the floor, or than the starting flight when that is
    shorter; without a floor the same refiner shortens the flight."""
    box = np.array([-2.0, -2.0, 0.5, 2.0, 2.0, 2.5])

    def refiner(shortest: float) -> PathRefiner:
        return PathRefiner(replace(_two_vertex_path(), dopt=2.0), feasible=lambda s: True,
                           stop_at=lambda v: StopChoice(None, None),
                           pricing=_shorter_is_better(), box=box, budget=10.0,
                           rng=np.random.default_rng(3), shortest_flight=shortest)

    free = refiner(0.0)
    for _ in range(300):
        free.step()
    assert free.path.duration < 1.8
    floored = refiner(floor)
    kept = []
    for _ in range(300):
        if floored.step():
            kept.append(floored.path.duration)
    assert min(kept, default=2.0) >= min(floor, 2.0) - 1e-12
