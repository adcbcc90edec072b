"""Tests of the rest-to-rest move time within an autopilot's limits (planner/move_time.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mavsysid.planner.kinematic_check import exceeded_limits
from mavsysid.planner.move_time import rest_to_rest_time
from mavsysid.planner.segments import VertexState, connect_fixed
from mavsysid.vehicle.kinematic_limits import KinematicLimits

#: ArduCopter's stock position-controller limits, SI (WPNAV_*, PSC_JERK_*, ANGLE_MAX,
#: ATC_SLEW_YAW, ATC_ACCEL_Y_MAX as `autopilot_limits.kinematic_limits` reads them).
STOCK = KinematicLimits(speed_xy=10.0, climb=2.5, descent=1.5, accel_xy=2.5, accel_up=1.0,
                        accel_down=1.0, jerk_xy=5.0, jerk_z=5.0, tilt=math.radians(30.0),
                        yaw_rate=math.radians(60.0), yaw_acceleration=math.radians(270.0))
#: A speed-, tilt- and total-jerk-bound envelope (PX4-like), and yaw acceleration only.
FAST = KinematicLimits(speed_xy=0.8, climb=0.5, descent=0.3, tilt=math.radians(10.0),
                       jerk=2.0, yaw_rate=math.radians(20.0))
YAW_ONLY = KinematicLimits(yaw_acceleration=1.0)


def _rest_to_rest(displacement, yaw: float, duration: float):
    start = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.3)
    end = VertexState.hover(start.position[0] + displacement, 0.3 + yaw)
    return connect_fixed(start, end, duration)


@pytest.mark.parametrize("limits", [STOCK, FAST, YAW_ONLY], ids=["stock", "fast", "yaw"])
@pytest.mark.parametrize(("displacement", "yaw"), [
    ((2.0, 0.0, 0.0), 0.0), ((0.0, -1.3, 0.0), 0.0), ((1.0, 1.0, 0.0), 0.0),
    ((0.0, 0.0, 0.8), 0.0), ((0.0, 0.0, -0.8), 0.0), ((0.0, 0.0, 0.0), 2.5),
    ((0.0, 0.0, 0.0), -1.0), ((1.5, 0.0, 0.0), 3.0),
], ids=["x", "y", "diagonal", "climb", "descent", "yaw", "yaw-back", "x-and-yaw"])
def test_the_move_time_is_the_shortest_within_the_limits(limits, displacement, yaw):
    """The planner's own rest-to-rest segment keeps the limits at the move time and breaks
    one 3 % faster (moves along one axis and yaw, where the bound is exact)."""
    d = np.array(displacement)
    t = rest_to_rest_time(d, yaw, limits)
    if limits is YAW_ONLY and yaw == 0.0:
        assert t == 0.0
        return
    assert t > 0.0
    assert exceeded_limits(_rest_to_rest(d, yaw, t * (1.0 + 1e-6)), limits) == ""
    assert exceeded_limits(_rest_to_rest(d, yaw, 0.97 * t), limits) != ""


def test_no_move_or_no_limit_takes_no_time():
    """A still move, or an envelope without limits, needs no time."""
    assert rest_to_rest_time(np.zeros(3), 0.0, STOCK) == 0.0
    assert rest_to_rest_time(np.array([3.0, 1.0, -1.0]), 2.0, KinematicLimits()) == 0.0


@pytest.mark.parametrize("scale", [0.25, 4.0])
def test_the_move_time_scales_as_the_binding_limit_says(scale):
    """Jerk-bound: T ∝ d^(1/3); acceleration-bound: T ∝ d^(1/2); speed-bound: T ∝ d."""
    d = np.array([1.0, 0.0, 0.0])
    for limits, power in ((KinematicLimits(jerk_xy=5.0), 1 / 3),
                          (KinematicLimits(accel_xy=2.5), 1 / 2),
                          (KinematicLimits(speed_xy=1.0), 1.0)):
        ratio = rest_to_rest_time(scale * d, 0.0, limits) / rest_to_rest_time(d, 0.0, limits)
        assert ratio == pytest.approx(scale**power, rel=1e-12)
