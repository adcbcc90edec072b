"""Autopilot position-controller limits against a plan: peaks, refusal, raising, restoring."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import (
    ARDUPILOT_LIMITS,
    PX4_LIMITS,
    apply_autopilot_limits,
    continuation_limit_refusals,
    kinematic_limits,
    limits_in_effect,
    raised_values,
    requirements,
)
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.kinematic_limits import (
    KinematicPeaks,
    exceeded,
    kinematic_peaks,
)
from mavsysid.vehicle.polynomial_extremes import tilt_angle
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError

#: ArduCopter's stock values (defaults in the ArduPilot 90700977 source).
STOCK = {"WPNAV_SPEED": 1000.0, "WPNAV_SPEED_UP": 250.0, "WPNAV_SPEED_DN": 150.0,
         "WPNAV_ACCEL": 250.0, "WPNAV_ACCEL_Z": 100.0, "PSC_JERK_XY": 5.0, "PSC_JERK_Z": 5.0,
         "ANGLE_MAX": 3000.0, "PSC_ANGLE_MAX": 0.0, "ATC_SLEW_YAW": 6000.0,
         "ATC_RATE_Y_MAX": 0.0, "ATC_ACCEL_Y_MAX": 27000.0, "ATC_ACCEL_R_MAX": 110000.0,
         "ATC_ACCEL_P_MAX": 110000.0, "ATC_RATE_FF_ENAB": 1.0}
PEAKS = KinematicPeaks(speed_xy=2.5, climb=1.0, descent=1.8, accel_xy=7.6, accel_up=2.0,
                       accel_down=2.5, jerk_xy=15.0, jerk_z=6.0, jerk=16.0,
                       tilt=math.atan2(7.6, GRAVITY), yaw_rate=math.radians(157.0),
                       yaw_acceleration=math.radians(400.0))


def _line(duration: float, distance: float) -> PiecewisePolynomial:
    """A rest-to-rest straight line along x (a quintic), whose peaks are known."""
    c = np.zeros((1, 3, 6))
    c[0, 0, 3:] = distance * np.array([10.0, -15.0, 6.0]) / duration ** np.array([3, 4, 5])
    c[0, 2, 0] = 1.0
    return PiecewisePolynomial(np.array([duration]), c, np.zeros((1, 6)))


def test_peaks_of_a_quintic_line_match_its_closed_form():
    T, d = 2.0, 3.0
    peaks = kinematic_peaks(_line(T, d))
    assert peaks.speed_xy == pytest.approx(15.0 / 8.0 * d / T, rel=1e-4)
    assert peaks.accel_xy == pytest.approx(10.0 / math.sqrt(3.0) * d / T**2, rel=1e-3)
    assert peaks.jerk_xy == pytest.approx(60.0 * d / T**3, rel=1e-3)
    assert peaks.climb == peaks.descent == peaks.yaw_rate == 0.0
    assert peaks.tilt == pytest.approx(math.atan2(peaks.accel_xy, GRAVITY), rel=1e-6)


def test_tilt_angle_is_the_thrust_direction_from_the_vertical():
    a = np.array([[0.0, 0.0, 0.0], [GRAVITY, 0.0, 0.0], [0.0, 3.0, -GRAVITY]])
    assert tilt_angle(a) == pytest.approx([0.0, math.pi / 4.0, math.pi / 2.0])


def test_stock_arducopter_refuses_the_issue_plan_naming_the_parameters():
    needs = requirements(Autopilot.ARDUPILOT, PEAKS, STOCK)
    tracking = {r.name for r in needs if r.tracking}
    assert {"PSC_JERK_XY", "PSC_JERK_Z", "ANGLE_MAX", "ATC_SLEW_YAW"} <= tracking
    # 4 j² / (g · 1100°/s²) with j = 15 m/s³: 4.78 m/s², above the stock 2.5 m/s².
    assert "WPNAV_ACCEL" in tracking
    assert "WPNAV_SPEED" not in {r.name for r in needs}


def test_raised_values_cover_the_plan_with_margin_and_stay_under_the_caps():
    needs = requirements(Autopilot.ARDUPILOT, PEAKS, STOCK)
    new = raised_values(Autopilot.ARDUPILOT, needs)
    raised = {**STOCK, **new}
    assert requirements(Autopilot.ARDUPILOT, PEAKS, raised) == []
    caps = {p.name: p.cap for p in ARDUPILOT_LIMITS}
    assert all(v <= caps[n] for n, v in new.items())
    assert new["ANGLE_MAX"] == float(round(new["ANGLE_MAX"]))
    assert not exceeded(PEAKS, kinematic_limits(Autopilot.ARDUPILOT, raised))
    # Only as far as needed: well below the caps here.
    assert new["ANGLE_MAX"] < 1.3 * math.degrees(PEAKS.tilt) * 100.0


def test_a_need_above_a_cap_is_refused_with_its_name():
    wild = KinematicPeaks(jerk_xy=40.0)
    with pytest.raises(JobFailedError, match="PSC_JERK_XY 40 m/s³ \\(cap 20\\)"):
        raised_values(Autopilot.ARDUPILOT, requirements(Autopilot.ARDUPILOT, wild, STOCK))


def test_px4_limits_and_zero_meaning_unlimited():
    values = {p.name: p.cap for p in PX4_LIMITS}
    assert requirements(Autopilot.PX4, PEAKS, values) == []
    values["MPC_TILTMAX_AIR"] = 30.0
    needs = requirements(Autopilot.PX4, PEAKS, values)
    assert [r.name for r in needs] == ["MPC_TILTMAX_AIR"]
    assert kinematic_limits(Autopilot.ARDUPILOT, {"ATC_RATE_Y_MAX": 0.0}).yaw_rate is None


class _FakeParameters:
    """A ParameterSession stand-in: a dict of values and a restore that puts them back."""

    def __init__(self, values: dict[str, float]) -> None:
        self.values = dict(values)
        self.original: dict[str, float] = {}

    def read(self, names, timeout: float = 5.0) -> dict[str, float]:
        return {n: self.values[n] for n in names if n in self.values}

    def set(self, name: str, value: float) -> None:
        self.original.setdefault(name, self.values[name])
        self.values[name] = value

    def restore(self) -> list[str]:
        self.values.update(self.original)
        return []


def test_apply_refuses_in_one_line_or_raises_for_the_flight():
    said: list[str] = []
    fake = _FakeParameters(STOCK)
    with pytest.raises(JobFailedError) as refused:
        apply_autopilot_limits(fake, Autopilot.ARDUPILOT, PEAKS, False, said.append)
    text = str(refused.value)
    assert "\n" not in text and "PSC_JERK_XY 5 < " in text and "ANGLE_MAX 3000 < " in text
    assert fake.values == STOCK
    apply_autopilot_limits(fake, Autopilot.ARDUPILOT, PEAKS, True, said.append)
    assert requirements(Autopilot.ARDUPILOT, PEAKS, fake.values) == []
    assert "raised" in said[-1]
    fake.restore()
    assert fake.values == STOCK


def test_the_excitation_figure_on_the_simulated_vehicle_defaults_is_not_refused():
    from mavsysid.flight.simvehicle.params import default_parameters
    from mavsysid.vehicle.config import load_vehicle

    peaks = kinematic_peaks(excitation_trajectory(ExcitationSpec(duration=12.0)))
    for autopilot in (Autopilot.ARDUPILOT, Autopilot.PX4):
        table = default_parameters(autopilot, load_vehicle("firefly"))
        values = {p.name: p.value for p in table}
        assert [r for r in requirements(autopilot, peaks, values) if r.tracking] == []


@pytest.mark.slow
def test_a_plan_made_for_stock_arducopter_passes_the_streams_limit_check():
    """plan --autopilot-limits (stock values) → the stream's pre-flight check of them."""
    from mavsysid.planner.rrbt import plan
    from mavsysid.planner.settings import PlannerSettings
    from mavsysid.vehicle.config import load_vehicle

    config = load_vehicle("quad_x")
    settings = PlannerSettings(budget=15.0, planning_time=math.inf, max_samples=400, seed=4,
                               refine_steps=300)
    free = kinematic_peaks(plan(config, settings).trajectory)
    # Without the option the planner asks for more than stock ArduCopter follows.
    assert [r for r in requirements(Autopilot.ARDUPILOT, free, STOCK) if r.tracking]
    limited = plan(config, replace(settings, autopilot_limits=kinematic_limits(
        Autopilot.ARDUPILOT, STOCK))).trajectory
    peaks = kinematic_peaks(limited)
    assert requirements(Autopilot.ARDUPILOT, peaks, STOCK) == []
    said: list[str] = []
    fake = _FakeParameters(STOCK)
    apply_autopilot_limits(fake, Autopilot.ARDUPILOT, peaks, False, said.append)
    within = ", ".join(p.name for p in ARDUPILOT_LIMITS)
    assert said == [f"autopilot limits: the plan is within {within}"] and fake.values == STOCK
    assert limited.duration > 5.0


def test_limits_in_effect_are_the_values_read_with_the_raised_ones() -> None:
    """--set-limits' flight values replace the values read; other parameters are ignored."""
    noted = {"read": dict(STOCK), "set_limits": True}
    changed = {"PSC_JERK_XY": (5.0, 18.0), "FENCE_TYPE": (0.0, 5.0)}
    values = limits_in_effect(noted, changed)
    assert values is not None
    assert values["PSC_JERK_XY"] == 18.0 and values["ANGLE_MAX"] == STOCK["ANGLE_MAX"]
    assert "FENCE_TYPE" not in values
    assert limits_in_effect(None, changed) is None
    assert limits_in_effect({"read": {}}, changed) is None


@pytest.mark.parametrize("duration", [1.0, 8.0])
def test_a_continuation_beyond_the_limits_in_effect_is_refused_in_one_line(
        duration: float) -> None:
    """A re-planned trajectory is refused exactly when a tracking limit is below its peaks."""
    line = _line(duration, 3.0)
    refusals = continuation_limit_refusals(Autopilot.ARDUPILOT, STOCK, line)
    tracking = [r for r in requirements(Autopilot.ARDUPILOT, kinematic_peaks(line), STOCK)
                if r.tracking]
    assert bool(refusals) == bool(tracking)
    assert len(refusals) <= 1 and all("\n" not in r for r in refusals)
    if tracking:
        assert all(r.name in refusals[0] for r in tracking)
