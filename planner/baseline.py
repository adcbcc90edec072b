"""The paper's random baseline: the same graph search, picking the path with the most
distinct segments ("this heuristic biases the random planner towards exciting all
directions and fast maneuvers", paper Section "Simulation Based Experiments")."""

from __future__ import annotations

from collections.abc import Callable

from mavsysid.planner.plan_result import PlanProgress, PlanResult
from mavsysid.planner.rrbt import search_graph
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["plan_random"]


def plan_random(config: VehicleConfig, settings: PlannerSettings | None = None,
                progress: Callable[[PlanProgress], None] | None = None) -> PlanResult:
    """A random calibration flight from the same motion graph as `mavsysid.planner.rrbt.plan`."""
    return search_graph(config, settings or PlannerSettings(), "random", progress)
