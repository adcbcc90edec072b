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

`search_result` turns the search and its chosen path into the `PlanResult`: the trajectory
with its stop, σ over time along it, the search statistics and the graph.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from mavsysid.planner.belief import edge_samples, propagate_steps
from mavsysid.planner.best_flight import refine_best
from mavsysid.planner.graph import logdet
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.plan_request import check_request
from mavsysid.planner.plan_result import (
    PlannerGraph,
    PlannerStats,
    PlanProgress,
    PlanResult,
    shortfall_note,
)
from mavsysid.planner.refine import RefinablePath
from mavsysid.planner.search_setup import initial_covariance, segment_trajectory, warm_up
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError

__all__ = ["plan", "search_graph", "search_result", "sigma_over_time"]


def search_graph(config: VehicleConfig, settings: PlannerSettings, objective: str,
                 progress: Callable[[PlanProgress], None] | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> PlanResult:
    """Run the graph search with an objective: "dopt" or "random" (most distinct segments),
    timed by ``clock`` (s; the wall clock by default)."""
    check_request(config, settings)
    warm_up(config, settings)
    search = GraphSearch(config, settings, objective, progress, clock)
    search.run()
    return search_result(search, objective, refine_best(search))


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


def search_result(search: GraphSearch, kind: str, path: RefinablePath | None) -> PlanResult:
    """The chosen flight: the (refined) best path plus its stop, with σ over time.

    Parameters
    ----------
    search : GraphSearch
        The finished search: its vehicle, settings, model and θ for the σ propagation, and
        its graph and counters for the statistics.
    kind : str
        "dopt" (the information-gathering planner) or "random" (the paper's baseline),
        as `PlanResult.kind`.
    path : RefinablePath or None
        The best flight found, refined, with its stopping segment; None when no feasible
        flight was found.

    Raises
    ------
    JobFailedError
        ``path`` is None: one line with the planning time and the graph's size.
    """
    if path is None:
        raise JobFailedError(
            f"no feasible trajectory found in {search.elapsed():.1f} s of planning "
            f"({search.samples} samples, {len(search.vertices)} vertices, {search.edges} edges)")
    segments = list(path.segments)
    if path.stop.segment is not None:
        segments.append(path.stop.segment)
    trajectory = PiecewisePolynomial(
        np.array([s.duration for s in segments]),
        np.array([s.position_coeffs for s in segments]),
        np.array([s.yaw_coeffs for s in segments]))
    model = search.model
    sigma = initial_covariance(model, search.config, search.settings)
    times, sig, sigma = sigma_over_time(search, trajectory, segments, sigma)
    final_cov = model.parameter_covariance_si(sigma)
    stats = PlannerStats(
        samples=search.samples, vertices=len(search.vertices), edges=search.edges,
        beliefs=sum(len(v.beliefs) for v in search.vertices),
        edges_attempted=search.edges_attempted, beliefs_propagated=search.propagations,
        elapsed=search.elapsed(), time_to_first_solution=search.first_solution,
        edge_time=search.edge_time + search.transfer_time,
        propagation_time=search.propagation_time,
        best_history=np.array(search.history, dtype=float).reshape(-1, 2),
        refine_steps=search.refined_steps, refine_accepted=search.refined_accepted,
        cpu_time=search.cpu_time(), search_stop=search.stopped_by,
        refusals=dict(search.refusals))
    assert search.best is not None
    search_path = [0] + [e.dst for e in search.best[1].path_edges()]
    edge_list = [e for v in search.vertices for e in v.out_edges]
    graph = PlannerGraph(
        vertices=np.array([v.state.pose for v in search.vertices]),
        edges=np.array([(e.src, e.dst) for e in edge_list], dtype=int).reshape(-1, 2),
        edge_paths=[e.segment.flat_outputs(np.linspace(0.0, e.segment.duration, 12)).position
                    for e in edge_list],
        path=search_path)
    return PlanResult(
        kind=kind, trajectory=trajectory,
        predicted_dopt=float(np.exp(logdet(final_cov) / 6.0)),
        predicted_covariance=final_cov, sigma_times=times,
        predicted_sigma=sig, config=search.config, settings=search.settings,
        stats=stats, graph=graph,
        shortfall=shortfall_note(trajectory.duration, search.settings, stats))


def sigma_over_time(search: GraphSearch, trajectory: PiecewisePolynomial, segments: list,
                    sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The predicted σ of θ along the chosen flight at the measurement rate, step by step
    (paper Eqs. prior–posterior): per segment on the flatness map, or on the whole flight
    the autopilot is predicted to fly (`PlannerSettings.autopilot`).

    Parameters
    ----------
    search : GraphSearch
        Its estimator model, θ and settings.
    trajectory : PiecewisePolynomial
        The whole flight, its stop included.
    segments : list of Segment
        Its segments, in order.
    sigma : ndarray, shape (18, 18)
        The belief at the start.

    Returns
    -------
    times : ndarray, shape (S,)
        s from the start.
    sigma_theta : ndarray, shape (S, 6)
        σ of θ, SI.
    final : ndarray, shape (18, 18)
        The belief at the end.
    """
    model, theta, rate = search.model, search.theta, search.settings.measurement_rate
    times, sig = [0.0], [np.sqrt(np.diag(model.parameter_covariance_si(sigma)))]
    autopilot = search.settings.autopilot
    pieces = [trajectory] if autopilot is not None else [segment_trajectory(s) for s in segments]
    t_offset = 0.0
    for piece in pieces:
        states, n, dt = edge_samples(piece, search.config, theta, rate, autopilot)
        history = propagate_steps(model, sigma, states, n, theta, dt)
        sigma = history[-1]
        si = model.parameter_covariance_si(history[1:])
        sig.extend(np.sqrt(np.diagonal(si, axis1=1, axis2=2)))
        times.extend(t_offset + dt * np.arange(1, len(history)))
        t_offset += piece.duration
    return np.array(times), np.array(sig), sigma
