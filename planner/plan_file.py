"""A planned flight as a trajectory file (`mavsysid.formats.trajectory_file`): the
segments with the planner's prediction and statistics."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.planner.plan_result import PlanResult
from mavsysid.vehicle.config import PARAMETER_NAMES

__all__ = ["plan_file_for", "write_trajectory"]


def _finite_or_none(value: float | None) -> float | None:
    """A JSON number, or None for a missing or non-finite value (an unlimited time, say)."""
    return None if value is None or not math.isfinite(value) else float(value)


def plan_file_for(result: PlanResult) -> dict[str, Any]:
    """The trajectory-file document of a planned flight (prediction and planner included)."""
    document = trajectory_file_for(result.trajectory, result.config, result.kind,
                                   result.settings.box)
    document["predicted_dopt"] = float(result.predicted_dopt)
    document["predicted_covariance"] = np.asarray(result.predicted_covariance, float).tolist()
    sigma = np.asarray(result.predicted_sigma, dtype=float)
    if sigma.size:
        document["predicted_sigma"] = {
            "t": np.asarray(result.sigma_times, dtype=float).tolist(),
            **{name: sigma[:, j].tolist() for j, name in enumerate(PARAMETER_NAMES)},
        }
    settings, stats = result.settings, result.stats
    document["planner"] = {
        **{k: getattr(settings, k) for k in ("seed", "budget", "max_samples",
                                             "measurement_rate", "prior_relative_sigma")},
        "planning_time": _finite_or_none(settings.planning_time),
        **{k: getattr(stats, k) for k in ("samples", "vertices", "edges", "beliefs",
                                          "edges_attempted", "beliefs_propagated", "elapsed")},
        "time_to_first_solution": _finite_or_none(stats.time_to_first_solution),
        "cpu_time": stats.cpu_time, "search_stop": stats.search_stop or None,
        "shortfall": result.shortfall or None,
        "refinement": {"share": settings.refine_share, "max_steps": settings.refine_steps,
                       "steps": stats.refine_steps, "accepted": stats.refine_accepted},
    }
    return document


def write_trajectory(path: str | Path, result: PlanResult) -> None:
    """Write a planned flight as a trajectory file, atomically (see `plan_file_for`)."""
    write_trajectory_file(path, plan_file_for(result))
