"""Stand-ins for the planner (``rrbt.plan``, ``baseline.plan_random``) that record their calls."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.planner.results import (
    PlannerGraph,
    PlannerSettings,
    PlannerStats,
    PlanProgress,
    PlanResult,
)
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["fake_result", "install_fake_planner"]


def fake_result(config: VehicleConfig, settings: PlannerSettings, kind: str) -> PlanResult:
    """A hand-made plan for the given request: the 12 s excitation figure, made-up σ."""
    trajectory = excitation_trajectory(ExcitationSpec(duration=12.0))
    t = np.linspace(0.0, trajectory.duration, 13)
    sigma = 0.5 * config.theta * np.exp(-t[:, None] / 4.0)
    covariance = np.diag(sigma[-1] ** 2)
    stats = PlannerStats(40, 12, 30, 50, 60, 80, 1.5, 0.2, 0.5, 0.7, np.zeros((0, 2)))
    graph = PlannerGraph(np.zeros((1, 4)), np.zeros((0, 2), dtype=int), [], [0])
    return PlanResult(kind, trajectory, float(np.prod(sigma[-1]) ** (1 / 3)), covariance, t,
                      sigma, config, settings, stats, graph)


def install_fake_planner(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, PlannerSettings]]:
    """Put stand-ins for ``mavsysid.planner.rrbt`` and ``.baseline`` in ``sys.modules``.

    Each call of a stand-in reports two progress steps and returns `fake_result`.

    Parameters
    ----------
    monkeypatch : pytest.MonkeyPatch
        Undoes the replacement after the test.

    Returns
    -------
    list of (str, PlannerSettings)
        The calls made, as (``"dopt"`` or ``"random"``, settings), filled as they happen.
    """
    calls: list[tuple[str, PlannerSettings]] = []

    def make(kind: str):
        def plan(config, settings, progress=None):
            calls.append((kind, settings))
            if progress is not None:
                progress(PlanProgress(0.5, 20, 7, 12, 30, None))
                progress(PlanProgress(1.0, 40, 12, 30, 50, 1e-6))
            return fake_result(config, settings, kind)
        return plan

    rrbt = types.ModuleType("mavsysid.planner.rrbt")
    baseline = types.ModuleType("mavsysid.planner.baseline")
    rrbt.plan = make("dopt")  # type: ignore[attr-defined]
    baseline.plan_random = make("random")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "mavsysid.planner.rrbt", rrbt)
    monkeypatch.setitem(sys.modules, "mavsysid.planner.baseline", baseline)
    return calls
