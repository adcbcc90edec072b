"""A finished planning run as a `PlanResult`: the trajectory, its predicted σ over time,
the search statistics, the graph (for the Rerun recording), and a plain note when the
flight is shorter than 90 % of the budget (`shortfall_note`)."""

from __future__ import annotations

import numpy as np
from mavsysid.planner.belief import edge_samples, propagate_steps
from mavsysid.planner.graph import logdet
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.refine import RefinablePath
from mavsysid.planner.results import (
    BUSY_CORE_SHARE,
    PlannerGraph,
    PlannerSettings,
    PlannerStats,
    PlanResult,
)
from mavsysid.planner.search_setup import initial_covariance, segment_trajectory
from mavsysid.planner.search_stop import FULL_FLIGHT_SHARE
from mavsysid.vehicle.kinematic_limits import KINEMATIC_WORDS
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError

__all__ = ["plan_result", "shortfall_note"]

#: The vehicle's constraints (`mavsysid.planner.feasibility.CONSTRAINTS`) in words.
_CONSTRAINT_WORDS = {
    "box": "the flight box", "thrust": "the vehicle's thrust range",
    "speed": "the vehicle's speed limit", "yaw_acceleration": "its yaw acceleration limit",
    "body_rate": "its body rate limit", "rotor_speed": "its rotor speed range"}


def _refusal_words(reason: str) -> str:
    if reason.startswith("autopilot "):
        return f"the autopilot's {KINEMATIC_WORDS[reason.split(' ', 1)[1]]} limit"
    return _CONSTRAINT_WORDS.get(reason, reason)


def shortfall_note(duration: float, settings: PlannerSettings, stats: PlannerStats) -> str:
    """One line when a planned flight uses less than 90 % of its budget, else "".

    Says how long the flight is, what stopped the search (its sample budget, or its
    share of the planning time, and how much of a core it had), how many sampled
    connections were feasible and what refused most of the others, and what to try.

    Parameters
    ----------
    duration : float
        The planned flight, stop included, s.
    settings : PlannerSettings
    stats : PlannerStats
        The run's statistics (``search_stop``, ``refusals``, ``cpu_time``, …).
    """
    budget = settings.budget
    if duration >= FULL_FLIGHT_SHARE * budget - 1e-9:  # the refinement may stop right at it
        return ""
    head = f"a {duration:.1f} s flight of the {budget:g} s budget ({100 * duration / budget:.0f} %)"
    if stats.search_stop == "samples":
        stop = f"the search stopped after its {stats.samples} samples"
        advice = f"try --samples {2 * stats.samples}"
    else:
        stop = f"the search stopped at its share of the {settings.planning_time:g} s planning time"
        share = stats.cpu_time / stats.elapsed if stats.elapsed > 0.0 else 1.0
        if share < BUSY_CORE_SHARE:
            stop += f" (the machine was busy: the planner had {100 * share:.0f} % of a core)"
        advice = f"try --time {2 * settings.planning_time:g}"
    why = ""
    if stats.edges_attempted:
        why = f"; {stats.edges} of {stats.edges_attempted} sampled connections were feasible"
        refused = sum(stats.refusals.values())
        if refused:
            top, count = max(stats.refusals.items(), key=lambda item: item[1])
            why += (f", {100 * count / refused:.0f} % of the others refused by "
                    f"{_refusal_words(top)}")
    return f"{head}: {stop}{why}; {advice}"


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
        predicted_covariance=final_cov, sigma_times=np.array(times),
        predicted_sigma=np.array(sig), config=search.config, settings=search.settings,
        stats=stats, graph=graph,
        shortfall=shortfall_note(trajectory.duration, search.settings, stats))
