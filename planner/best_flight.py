"""The graph search's best flight as a path, and its refinement in the rest of the
planning time (`mavsysid.planner.refine`, beyond the paper)."""

from __future__ import annotations

import numpy as np
from mavsysid.planner.belief import apply_transfer, identity_transfer
from mavsysid.planner.feasibility import segment_slack
from mavsysid.planner.gradient_refine import GradientRefiner
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.refine import (
    FlightPricing,
    PathRefiner,
    RefinablePath,
    StopChoice,
    split_path,
)
from mavsysid.planner.search_stop import FULL_FLIGHT_SHARE
from mavsysid.planner.yaw_branch import shift_segment_yaw, shift_vertex_yaw

__all__ = ["best_path", "refine_best"]


def best_path(search: GraphSearch) -> RefinablePath | None:
    """The best candidate flight found by the search, its yaw made continuous.

    An edge ends at its destination's yaw shifted by 2πk (`nearest_yaw_branch`), and
    the next edge starts from the unshifted vertex. Each segment (and the stop) is
    shifted by whole turns to start where the previous one ended, so that the path's
    vertices are its segments' own boundary states and a re-solved segment turns the
    way the searched one did (else the refinement would see 2π yaw jumps).
    """
    if search.best is None:
        return None
    belief = search.best[1]
    edges = belief.path_edges()
    end = search.vertices[belief.vertex]
    transfers = tuple(search.edge_transfer(e) for e in edges)
    vertices, segments = [search.vertices[0].state], []
    for edge in edges:
        segment = shift_segment_yaw(edge.segment, float(vertices[-1].yaw[0])
                                    - float(edge.segment.yaw_coeffs[0]))
        segments.append(segment)
        dst = search.vertices[edge.dst].state
        vertices.append(shift_vertex_yaw(dst, float(segment.end_state().yaw[0])
                                         - float(dst.yaw[0])))
    stop_segment_ = None if end.stop is None else shift_segment_yaw(
        end.stop, float(vertices[-1].yaw[0]) - float(end.stop.yaw_coeffs[0]))
    stop = StopChoice(stop_segment_, end.stop_transfer)
    return RefinablePath(tuple(vertices), tuple(segments), transfers, stop,
                         search.flight_dopt([*transfers, stop.transfer]))


def refine_best(search: GraphSearch, gradient: bool = False) -> RefinablePath | None:
    """Spend the rest of the planning time refining the search's best flight.

    With ``gradient`` the refinement mixes block-gradient steps with the ES
    (`mavsysid.planner.gradient_refine`); its steps count pricings. Records the steps
    taken and kept on ``search`` (``refined_steps``, ``refined_accepted``) and each
    improvement in its ``history``.
    """
    path = best_path(search)
    if path is None or search.refine_steps == 0:
        return path
    settings = search.settings
    pricing = FlightPricing(search.sigma0, search.propagate_segments, search.kept_transfer,
                            apply_transfer, search.dopt, identity_transfer(search.model.dim))
    path = split_path(path, settings.refine_split, search.feasible, search.transfer_of)
    es = PathRefiner(path, search.feasible,
                     lambda state: search.stop_at(state, with_transfer=False), pricing,
                     search.box, settings.budget, np.random.default_rng([settings.seed, 1]),
                     search.longest_segment, FULL_FLIGHT_SHARE * settings.budget)
    refiner: PathRefiner | GradientRefiner = es
    if gradient:
        # The barrier keeps gradient steps off the rotor and body-rate limits, where the
        # refined flight sits and plain steps mostly fail the feasibility check.
        spread = search.theta_covariance
        refiner = GradientRefiner(es, slack=lambda segment: segment_slack(
            segment, search.config, rotor_headroom=settings.rotor_headroom,
            theta_covariance=spread, rotor_confidence=settings.rotor_confidence))
    while refiner.steps < search.refine_steps and search.elapsed() < settings.planning_time:
        if refiner.step():
            search.history.append((search.elapsed(), refiner.path.dopt))
        search.report()
    search.refined_steps, search.refined_accepted = refiner.steps, refiner.accepted
    search.report(force=True)
    return refiner.path
