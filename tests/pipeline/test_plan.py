"""Tests of the plan job (`mavsysid.pipeline.plan.run_plan`): checks, progress, failures."""

from __future__ import annotations

import sys

import pytest
from mavsysid.pipeline.plan import run_plan
from mavsysid.planner.plan_result import PlanProgress
from mavsysid.planner.settings import PlannerSettings
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


# --- the preview before a flight ---------------------------------------------------------

def _excitation(speedup: float):
    """The built-in 10 s excitation figure flown ``speedup`` times faster."""
    import json

    from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
    from mavsysid.formats.trajectory_file import parse_trajectory, trajectory_file_for

    from tests.support.mutated_trajectories import scale_time

    figure = excitation_trajectory(ExcitationSpec(duration=10.0))
    doc = json.loads(json.dumps(trajectory_file_for(figure, load_vehicle("firefly"),
                                                    "excitation", None)))
    return parse_trajectory(scale_time(doc, speedup), "figure").trajectory


@pytest.mark.parametrize("speedup", [1.0, 1.6])
def test_preview_peaks_agree_with_the_trajectory(speedup):
    """The preview's speed, thrust and tilt are the trajectory's own, sampled finely."""
    import numpy as np
    from mavsysid.pipeline.plan import preview_plan
    from mavsysid.vehicle.constants import GRAVITY

    trajectory = _excitation(speedup)
    preview = preview_plan(trajectory, load_vehicle("firefly"))
    flat = trajectory.flat_outputs(np.linspace(0.0, trajectory.duration, 20001))
    thrust_axis = flat.acceleration + np.array([0.0, 0.0, GRAVITY])
    norm = np.linalg.norm(thrust_axis, axis=1)
    assert preview.speed == pytest.approx(np.max(np.linalg.norm(flat.velocity, axis=1)),
                                          rel=1e-3)
    assert preview.thrust == pytest.approx(np.max(norm) / GRAVITY, rel=1e-3)
    assert preview.tilt == pytest.approx(np.max(np.arccos(thrust_axis[:, 2] / norm)), rel=1e-3)
    assert 0.0 <= preview.saturation <= 1.0 and preview.body_rate > 0.0


def test_preview_sees_saturation_in_a_fast_flight():
    """The figure at its own pace leaves the rotors free; 1.6 times faster it saturates
    them well beyond the warning threshold, and `plan` warns."""
    from mavsysid.pipeline.plan import SATURATION_WARNING, preview_plan

    from mavsysid.cli.plan import saturation_warning

    firefly = load_vehicle("firefly")
    calm, fast = (preview_plan(_excitation(k), firefly) for k in (1.0, 1.6))
    assert calm.saturation <= SATURATION_WARNING and saturation_warning(calm) is None
    assert fast.saturation > 10 * SATURATION_WARNING
    assert "rotors predicted saturated in" in saturation_warning(fast)


def test_margins_hold_back_part_of_the_envelope():
    """with_margins scales body rate, yaw acceleration and thrust above hover; a share
    outside [0, 1) is bad input."""
    from mavsysid.pipeline.plan import with_margins

    firefly = load_vehicle("firefly")
    held = with_margins(firefly, 0.3, 0.3, 0.3).limits
    lim = firefly.limits
    assert held.body_rate_max == pytest.approx(0.7 * lim.body_rate_max)
    assert held.yaw_acceleration_max == pytest.approx(0.7 * lim.yaw_acceleration_max)
    assert held.thrust_max_ratio - 1.0 == pytest.approx(0.7 * (lim.thrust_max_ratio - 1.0))
    assert with_margins(firefly).limits == lim
    with pytest.raises(InputError, match="--thrust-margin 1: expected a share in"):
        with_margins(firefly, thrust=1.0)
