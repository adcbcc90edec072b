"""Tests of the gradient steps of the refinement (planner/gradient_refine.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.planner.belief import apply_transfer, identity_transfer
from mavsysid.planner.best_flight import best_path, refine_best
from mavsysid.planner.gradient_refine import (
    BLOCK_SIZE,
    GradientRefiner,
    block_gradient,
    moved_block,
)
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.refine import FlightPricing, PathRefiner, split_path
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

from tests.support.refined_paths import assert_consistent_flight

# The chance constraint at a ±50 % prior leaves little to refine; these tests are about the
# optimiser, so the rotor check is at the prior θ.
_SETTINGS = PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=150, seed=4,
                            refine_steps=300, rotor_confidence=0.0)


@pytest.fixture(scope="module")
def searched():
    """A finished search and its best flight, split as the refinement sees it."""
    search = GraphSearch(load_vehicle("firefly"), _SETTINGS, "dopt", None)
    search.run()
    path = split_path(best_path(search), 2, search.feasible, search.transfer_of)
    return search, path


def _refiner(search, path, seed: int = 3) -> PathRefiner:
    return PathRefiner(path, search.feasible, lambda v: search.stop_at(v, False),
                       FlightPricing(search.sigma0, search.propagate_segments,
                                     search.kept_transfer, apply_transfer, search.dopt,
                                     identity_transfer()),
                       search.box, search.settings.budget, np.random.default_rng(seed),
                       search.config.limits.segment_time_max)


def _dopt_from_scratch(search, refiner, i: int, u: np.ndarray) -> float:
    """D-opt of the moved flight priced from the start with fresh transfers (no cache)."""
    vertices, durations = moved_block(refiner.path, i, u, refiner.lo, refiner.hi)
    moved = refiner.candidate(vertices, durations, [i - 1, i], check=False)[0]
    stop = moved.stop.transfer
    return search.flight_dopt([*(search.transfer_of(s) for s in moved.segments), stop])


def test_gradient_matches_a_central_difference_of_the_priced_dopt(searched):
    """Each component of the block gradient equals a central difference of log D-opt with
    the flight re-priced from scratch (no cached prefix), in a few random directions."""
    search, path = searched
    refiner = _refiner(search, path)
    i = len(path.segments) // 2
    _, gradient = block_gradient(refiner, i, step=1e-4)
    assert np.linalg.norm(gradient) > 0.0
    rng = np.random.default_rng(0)
    for _ in range(3):
        d = rng.normal(size=BLOCK_SIZE)
        d /= np.linalg.norm(d)
        h = 1e-3
        slope = (np.log(_dopt_from_scratch(search, refiner, i, h * d))
                 - np.log(_dopt_from_scratch(search, refiner, i, -h * d))) / (2 * h)
        assert gradient @ d == pytest.approx(slope, rel=0.05, abs=1e-3 * np.abs(gradient).max())


def test_gradient_steps_lower_the_dopt_and_keep_the_flight_feasible(searched):
    """Kept gradient steps lower the D-opt (the cached price equals a fresh one) and every
    segment stays feasible and the flight within the budget."""
    search, path = searched
    refiner = GradientRefiner(_refiner(search, path))
    kept = [refiner.gradient_step(i) for i in range(1, len(path.segments))]
    final = refiner.path
    assert any(kept) and final.dopt < path.dopt
    assert_consistent_flight(search, final)


def test_barrier_refuses_steps_that_reach_the_limit(searched):
    """With a barrier whose slack is at the limit for every segment, no step is kept."""
    search, path = searched
    refiner = GradientRefiner(_refiner(search, path), slack=lambda segment: 0.0)
    assert not any(refiner.gradient_step(i) for i in range(1, min(4, len(path.segments))))
    assert refiner.path is path


@pytest.mark.slow
def test_same_seed_same_refined_flight():
    """The mixed refinement with a step budget is a function of the seed."""
    def refined():
        search = GraphSearch(load_vehicle("firefly"), replace(_SETTINGS, refine_steps=200),
                             "dopt", None)
        search.run()
        return refine_best(search, gradient=True)
    a, b = refined(), refined()
    assert a.dopt == b.dopt
    for sa, sb in zip(a.segments, b.segments, strict=True):
        np.testing.assert_array_equal(sa.position_coeffs, sb.position_coeffs)
        np.testing.assert_array_equal(sa.yaw_coeffs, sb.yaw_coeffs)
