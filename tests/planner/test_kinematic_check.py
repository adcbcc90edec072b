"""The planner's autopilot envelope (``plan --autopilot-limits``): segment peaks, rejection,
validation."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.planner.kinematic_check import PLAN_SHARE, exceeded_limits, segment_peaks
from mavsysid.planner.plan_request import check_request
from mavsysid.planner.search_setup import segment_trajectory
from mavsysid.planner.segments import VertexState, connect_free_end
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.kinematic_limits import KINEMATIC_FIELDS, KinematicLimits, kinematic_peaks

from mavsysid.errors import InputError


def _segments(count: int, seed: int):
    """Seeded free-end segments from hover to random poses in the default box."""
    rng = np.random.default_rng(seed)
    start = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    for _ in range(count):
        end = rng.uniform([-1.8, -1.8, 0.7], [1.8, 1.8, 2.3])
        yield connect_free_end(start, end, float(rng.uniform(-3.0, 3.0)),
                               float(rng.uniform(0.6, 3.0)))


def test_segment_peaks_are_the_trajectory_peaks():
    for segment in _segments(5, seed=1):
        mine = segment_peaks(segment)
        theirs = kinematic_peaks(segment_trajectory(segment))
        for name in KINEMATIC_FIELDS:
            assert getattr(mine, name) == pytest.approx(getattr(theirs, name), rel=1e-9,
                                                        abs=1e-12), name


@pytest.mark.parametrize("name", ["accel_xy", "jerk_xy", "jerk_z", "tilt", "yaw_rate",
                                  "yaw_acceleration", "speed_xy", "accel_up"])
def test_a_segment_beyond_the_share_of_a_limit_is_rejected_by_that_limit(name):
    for segment in _segments(6, seed=2):
        peak = getattr(segment_peaks(segment), name)
        if peak <= 0.0:
            continue
        assert exceeded_limits(segment, KinematicLimits(**{name: 1.001 * peak / PLAN_SHARE})) == ""
        assert exceeded_limits(segment, KinematicLimits(**{name: 0.999 * peak / PLAN_SHARE})
                               ) == name
        assert exceeded_limits(segment, KinematicLimits()) == ""


@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan])
def test_a_limit_that_is_not_positive_is_refused_in_one_line(value):
    settings = PlannerSettings(max_samples=5, planning_time=math.inf)
    bad = replace(settings, autopilot_limits=KinematicLimits(tilt=value))
    with pytest.raises(InputError, match=r"^--autopilot-limits: tilt"):
        check_request(load_vehicle("quad_x"), bad)
    check_request(load_vehicle("quad_x"), replace(settings, autopilot_limits=KinematicLimits(
        tilt=0.5)))
