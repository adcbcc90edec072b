"""The information-gathering planner (paper Algorithm 1, Sections "Information Gathering
Algorithm" to "Pruning and Optimality"): an RRBT-style search of belief space.

Phase 1 grows a bidirectional motion graph: a sampled pose is connected from its nearest
vertex by a free-end minimum-snap segment (which fixes the new vertex's derivatives),
then to and from every vertex by fully constrained segments; only feasible segments
become edges, each with its precomputed one-step covariance transfer. Phase 2 pushes
the open beliefs of every vertex that gained an edge through all new path combinations,
pruning with the paper's modular comparison (Eq. compare). Every vertex carries a
stopping segment to hover, and a belief is a candidate flight only with its stop
appended and the whole inside the budget; the best candidate minimises the D-optimality
det(Σ_θ)^(1/6) (paper Eq. dopt, in log space).

The search itself is `mavsysid.planner.graph_search.GraphSearch`. It gets the first
1 − refine_share of the planning time; the rest refines its best flight
(`mavsysid.planner.best_flight`, `mavsysid.planner.refine`, beyond the paper). The request
is checked first (`mavsysid.planner.plan_request`). The search core is shared with
the random baseline (`mavsysid.planner.baseline`), which keeps the same graph and picks the
path with the most distinct segments instead.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from mavsysid.planner.best_flight import refine_best
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.plan_request import check_request
from mavsysid.planner.plan_result import plan_result
from mavsysid.planner.results import PlannerSettings, PlanProgress, PlanResult
from mavsysid.planner.search_setup import warm_up
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["plan", "search_graph"]


def search_graph(config: VehicleConfig, settings: PlannerSettings, objective: str,
                 progress: Callable[[PlanProgress], None] | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> PlanResult:
    """Run the graph search with an objective: "dopt" or "random" (most distinct segments),
    timed by ``clock`` (s; the wall clock by default)."""
    check_request(config, settings)
    warm_up(config, settings)
    search = GraphSearch(config, settings, objective, progress, clock)
    search.run()
    return plan_result(search, objective, refine_best(search))


def plan(config: VehicleConfig, settings: PlannerSettings | None = None,
         progress: Callable[[PlanProgress], None] | None = None,
         clock: Callable[[], float] = time.perf_counter) -> PlanResult:
    """Plan the flight within the budget that minimises the predicted D-optimality.

    ``settings.planning_time`` is measured on ``clock`` (s; the wall clock by default).
    A flight shorter than 90 % of the budget comes with `PlanResult.shortfall` saying why.

    Raises
    ------
    InputError
        Bad box, budget or limits.
    JobFailedError
        No feasible trajectory was found in the planning time.
    """
    return search_graph(config, settings or PlannerSettings(), "dopt", progress, clock)
