"""What the planner returns: progress reports, search statistics, the graph (for the Rerun
recording) and the planned flight (`PlanResult`), with a plain note when the flight is
shorter than 90 % of the budget (`shortfall_note`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mavsysid.planner.search_stop import FULL_FLIGHT_SHARE
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.kinematic_limits import KINEMATIC_WORDS
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["BUSY_CORE_SHARE", "PlanProgress", "PlanResult", "PlannerGraph", "PlannerStats",
           "shortfall_note"]

#: A planner with less than this share of a core (CPU time over planning time) ran on a
#: busy machine, and says so.
BUSY_CORE_SHARE = 0.8


@dataclass(frozen=True)
class PlanProgress:
    """A progress report, sent to the progress callback while planning."""

    elapsed: float
    samples: int
    vertices: int
    edges: int
    beliefs: int
    best_dopt: float | None


@dataclass(frozen=True)
class PlannerStats:
    """How a planning run went.

    Attributes
    ----------
    samples, vertices, edges, beliefs : int
        Sampled states, graph vertices, feasible edges, beliefs kept (open + closed).
    edges_attempted : int
        Connections tried (feasible or not).
    beliefs_propagated : int
        Belief propagations along edges (kept or pruned).
    elapsed : float
        Planning time, s, on the planner's clock (the wall clock unless one was given).
    time_to_first_solution : float or None
        Wall time until the first feasible plan, s.
    edge_time, propagation_time : float
        Wall time spent building edges (segments, feasibility, transfers) and propagating
        beliefs, s.
    best_history : ndarray, shape (H, 2)
        (elapsed s, best D-opt) each time the best plan improved, in the search and then
        in the refinement.
    refine_steps, refine_accepted : int
        Refinement perturbations tried and kept (`mavsysid.planner.refine`).
    cpu_time : float
        CPU time of the planning thread, s: below ``elapsed`` on a busy machine.
    search_stop : str
        What ended the graph search: "samples" (``max_samples``), "time" (its share of the
        planning time, with a flight shorter than 90 % of the budget), "filled" (its share
        of the planning time, with a flight that fills the budget); "" if unknown.
    refusals : dict of str to int
        Sampled connections refused, by reason: a constraint of
        `mavsysid.planner.feasibility.CONSTRAINTS`, or "autopilot QUANTITY" for a limit of
        ``PlannerSettings.autopilot_limits``.
    """

    samples: int
    vertices: int
    edges: int
    beliefs: int
    edges_attempted: int
    beliefs_propagated: int
    elapsed: float
    time_to_first_solution: float | None
    edge_time: float
    propagation_time: float
    best_history: np.ndarray
    refine_steps: int = 0
    refine_accepted: int = 0
    cpu_time: float = 0.0
    search_stop: str = ""
    refusals: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class PlannerGraph:
    """The motion graph, for display.

    Attributes
    ----------
    vertices : ndarray, shape (V, 4)
        [x, y, z, yaw] of each vertex.
    edges : ndarray, shape (E, 2)
        (from, to) vertex indices of each feasible edge.
    edge_paths : list of ndarray, each shape (P, 3)
        Sampled positions along each edge.
    path : list of int
        Vertex indices of the search's best path (start vertex first); the flown
        trajectory is this path after refinement.
    """

    vertices: np.ndarray
    edges: np.ndarray
    edge_paths: list[np.ndarray]
    path: list[int]


@dataclass(frozen=True)
class PlanResult:
    """A planned calibration flight.

    Attributes
    ----------
    kind : str
        "dopt" (the information-gathering planner) or "random" (the paper's baseline).
    trajectory : PiecewisePolynomial
        The flight, from hover at the start to hover at the end (stopping segment included).
    predicted_dopt : float
        Predicted D-optimality det(Σ_θ)^(1/6) at the end of the flight, SI units.
    predicted_covariance : ndarray, shape (6, 6)
        Predicted final θ covariance, SI.
    sigma_times : ndarray, shape (M,)
        Times along the flight, s.
    predicted_sigma : ndarray, shape (M, 6)
        Predicted σ of each parameter at those times, SI.
    config : VehicleConfig
        The vehicle (its nominal θ is the planner's model).
    settings : PlannerSettings
    stats : PlannerStats
    graph : PlannerGraph
    shortfall : str
        "" when the flight uses at least 90 % of the budget, else one line saying how
        short it is, why, and what to try (`mavsysid.planner.plan_result.shortfall_note`).
    """

    kind: str
    trajectory: PiecewisePolynomial
    predicted_dopt: float
    predicted_covariance: np.ndarray
    sigma_times: np.ndarray
    predicted_sigma: np.ndarray
    config: VehicleConfig
    settings: PlannerSettings
    stats: PlannerStats
    graph: PlannerGraph = field(repr=False)
    shortfall: str = ""


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
