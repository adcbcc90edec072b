"""Tests of the plan job (`mavsysid.pipeline.plan.run_plan`): checks, progress, failures."""

from __future__ import annotations

import sys

import pytest
from mavsysid.pipeline.plan import run_plan
from mavsysid.planner.results import PlannerSettings, PlanProgress
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError, JobFailedError
from tests.support.fake_planner import install_fake_planner


@pytest.fixture
def fake_planner(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, PlannerSettings]]:
    """Stand-ins for the planner's rrbt.plan and baseline.plan_random; records the calls."""
    return install_fake_planner(monkeypatch)


def test_failure_message_says_how_far_planning_got(fake_planner, monkeypatch):
    """A planner failure without the standard wording is prefixed with time and graph size."""
    def fail(config, settings, progress=None):
        progress(PlanProgress(3.5, 90, 17, 4, 20, None))
        raise JobFailedError("every edge leaves the box")

    monkeypatch.setattr(sys.modules["mavsysid.planner.rrbt"], "plan", fail)
    with pytest.raises(JobFailedError, match=r"^no feasible trajectory found in 3\.5 s "
                       r"\(17 vertices, 4 edges\): every edge leaves the box$"):
        run_plan("firefly", PlannerSettings(), progress=False)


def test_run_plan_forwards_progress(fake_planner):
    """A progress callable given to run_plan receives the planner's reports."""
    seen: list[PlanProgress] = []
    result = run_plan(load_vehicle("firefly"), PlannerSettings(max_samples=40),
                      progress=seen.append)
    assert [p.samples for p in seen] == [20, 40] and result.kind == "dopt"


def test_run_plan_checks_before_planning(fake_planner):
    """run_plan refuses an impossible request itself, without calling the planner."""
    with pytest.raises(InputError, match="--budget"):
        run_plan("firefly", PlannerSettings(budget=0.0))
    assert not fake_planner
