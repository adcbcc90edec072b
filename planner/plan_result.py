"""A finished planning run as a `PlanResult`: the trajectory, its predicted σ over time,
the search statistics and the graph (for the Rerun recording)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from mavsysid.planner.belief import edge_samples, propagate_steps
from mavsysid.planner.graph import logdet
from mavsysid.planner.refine import RefinablePath
from mavsysid.planner.results import PlannerGraph, PlannerStats, PlanResult
from mavsysid.planner.search_setup import initial_covariance, segment_trajectory
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError

if TYPE_CHECKING:
    from mavsysid.planner.graph_search import GraphSearch

__all__ = ["plan_result"]


def plan_result(search: GraphSearch, kind: str, path: RefinablePath | None) -> PlanResult:
    """The chosen flight: the (refined) best path plus its stop, with σ over time."""
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
    model, theta, rate = search.model, search.theta, search.settings.measurement_rate
    sigma = initial_covariance(model, search.config, search.settings)
    times, sig = [0.0], [np.sqrt(np.diag(model.parameter_covariance_si(sigma)))]
    t_offset = 0.0
    for segment in segments:
        states, n, dt = edge_samples(segment_trajectory(segment), search.config, theta, rate)
        history = propagate_steps(model, sigma, states, n, theta, dt)
        sigma = history[-1]
        si = model.parameter_covariance_si(history[1:])
        sig.extend(np.sqrt(np.diagonal(si, axis1=1, axis2=2)))
        times.extend(t_offset + dt * np.arange(1, len(history)))
        t_offset += segment.duration
    final_cov = model.parameter_covariance_si(sigma)
    stats = PlannerStats(
        samples=search.samples, vertices=len(search.vertices), edges=search.edges,
        beliefs=sum(len(v.beliefs) for v in search.vertices),
        edges_attempted=search.edges_attempted, beliefs_propagated=search.propagations,
        elapsed=search.elapsed(), time_to_first_solution=search.first_solution,
        edge_time=search.edge_time + search.transfer_time,
        propagation_time=search.propagation_time,
        best_history=np.array(search.history, dtype=float).reshape(-1, 2),
        refine_steps=search.refined_steps, refine_accepted=search.refined_accepted)
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
        predicted_covariance=final_cov, sigma_times=np.array(times),
        predicted_sigma=np.array(sig), config=search.config, settings=search.settings,
        stats=stats, graph=graph)
