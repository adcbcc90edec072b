"""Score a simulated flight's log through what ``mavsysid estimate`` runs, not the bare filter.

`bench/planner_baselines.py` scores every kind by the paper's EKF from the prior. A
researcher reads the tool's answer instead: `estimate_parameters` (robust start, filter,
batch refinement, HAC σ) and the checks that refuse (`check_result`, exit 3), or, with
``--auto-effects``, the re-estimate with the effects `diagnose` names
(`estimate_with_named_effects`). This is the comparison that decides whether a planned
flight "buys σ with bias" under mismatch.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mavsysid.estimation import check_result
from mavsysid.estimation.filter.estimator import estimate_parameters
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import Z95
from mavsysid.pipeline.auto_effects import estimate_with_named_effects
from mavsysid.vehicle.config import VehicleConfig

from bench.mismatch_coverage import scored
from mavsysid.errors import JobFailedError

__all__ = ["ESTIMATORS", "tool_scores"]

#: ``--estimator`` choices beside the bare filter.
ESTIMATORS = ("estimate", "auto-effects")


def tool_scores(directory: Path, prior: VehicleConfig, truth: np.ndarray, estimator: str
                ) -> dict:
    """The tool's final θ on the pose log in ``directory``, scored against ``truth``.

    Returns
    -------
    dict
        ``tool_error`` |θ̂ − θ| / θ (6,), NaN when refused; ``tool_covered`` whether each
        95 % interval covers the truth (False when refused); ``tool_refused`` the refusal's
        one line or None; ``tool_named`` the effects named (``auto-effects``).
    """
    flight = load_flight(directory / "pose.csv", prior)
    named: tuple = ()
    try:
        if estimator == "auto-effects":
            result, named = estimate_with_named_effects(flight, prior)
        else:
            result = estimate_parameters(flight, prior)
        check_result(flight.source, result)
    except JobFailedError as exc:
        return {"tool_error": np.full(6, np.nan), "tool_covered": [False] * 6,
                "tool_refused": str(exc).splitlines()[0], "tool_named": []}
    value, sigma = scored(result, prior)
    error = np.abs(value - truth)
    return {"tool_error": error / truth, "tool_covered": (error <= Z95 * sigma).tolist(),
            "tool_refused": None, "tool_named": [e.name for e in named]}
