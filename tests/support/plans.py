"""A hand-made `PlanResult` for testing what consumes plans (files, recordings)."""

from __future__ import annotations

import math

import numpy as np
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.planner.plan_result import PlannerGraph, PlannerStats, PlanResult
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

__all__ = ["fake_plan"]


def fake_plan(planning_time: float = 20.0, history: int = 25) -> PlanResult:
    """The 12 s excitation figure with a made-up σ history, graph and search history.

    ``history=0`` gives a plan without σ history (identity final covariance).
    """
    config = load_vehicle("firefly")
    trajectory = excitation_trajectory(ExcitationSpec(duration=12.0))
    t = np.linspace(0.0, trajectory.duration, history)
    sigma = 0.5 * config.theta * (0.02 + 0.98 * np.exp(-t[:, None] / 2.0))
    correlation = np.full((6, 6), 0.3) + 0.7 * np.eye(6)
    covariance = correlation * np.outer(sigma[-1], sigma[-1]) if history else np.eye(6)
    knots = trajectory.flat_outputs(np.concatenate([trajectory.segment_starts,
                                                    [trajectory.duration]]))
    vertices = np.column_stack([knots.position, knots.yaw])
    edges = np.column_stack([np.arange(len(vertices) - 1), np.arange(1, len(vertices))])
    paths = [np.linspace(vertices[a, :3], vertices[b, :3], 5) for a, b in edges]
    stats = PlannerStats(40, len(vertices), len(edges), 90, 200, 400, 2.5, 0.4, 1.0, 1.2,
                         np.array([[0.4, 1e-5], [2.0, 1e-6]]))
    # The excitation figure starts at rest at centre + amplitude.
    settings = PlannerSettings(budget=12.0, planning_time=planning_time, max_samples=40,
                               start=(1.3, 1.0, 1.9, 0.0), seed=1)
    dopt = math.exp(np.linalg.slogdet(covariance)[1] / 6.0)
    return PlanResult("dopt", trajectory, dopt, covariance, t, sigma, config, settings, stats,
                      PlannerGraph(vertices, edges, paths, [0, 3, 5]))
