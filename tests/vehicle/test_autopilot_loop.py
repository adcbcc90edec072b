"""Tests of the autopilot closed-loop model (`mavsysid.vehicle.autopilot_loop`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle import arducopter_loop
from mavsysid.vehicle.autopilot_loop import (
    ARDUCOPTER_LOOP_DEFAULTS,
    AutopilotLoop,
    fly,
    torque_per_output,
    yaw_damping,
)
from mavsysid.vehicle.config import GRAVITY, load_vehicle
from mavsysid.vehicle.loop_math import inverse_sqrt_controller, sqrt_controller
from mavsysid.vehicle.rotation import wrap_angle
from mavsysid.vehicle.trajectory import FlatOutputs

#: The limits `mavsysid sim` reports as ArduPilot (its controller has none of them).
SIM_LIMITS = {"PSC_JERK_XY": 1000.0, "PSC_JERK_Z": 1000.0, "ANGLE_MAX": 8000.0,
              "ATC_SLEW_YAW": 100000.0, "ATC_RATE_Y_MAX": 0.0, "ATC_ACCEL_Y_MAX": 0.0,
              "WPNAV_ACCEL": 250.0}


@dataclass(frozen=True)
class Step:
    """Hover at ``start`` until ``at``, then a setpoint at ``end`` (no feed-forward)."""

    start: tuple[float, float, float, float]
    end: tuple[float, float, float, float]
    at: float = 0.1
    duration: float = 8.0

    def flat_outputs(self, t: np.ndarray) -> FlatOutputs:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        pose = np.where((t >= self.at)[:, None], np.array(self.end), np.array(self.start))
        zero = np.zeros((t.size, 3))
        return FlatOutputs(pose[:, :3], zero, zero, zero, zero, pose[:, 3], zero[:, 0],
                           zero[:, 0])


@pytest.fixture(scope="module")
def sitl_quad():
    return load_vehicle("sitl_quad")


def test_sqrt_controller_is_continuous_and_inverted():
    """The square-root branch joins the linear one, bounds the rate's change, and
    `inverse_sqrt_controller` finds the error of a given output."""
    gain, limit = 2.0, 3.0
    corner = limit / gain**2
    below, above = sqrt_controller(corner * (1 - 1e-9), gain, limit, 0.0), \
        sqrt_controller(corner * (1 + 1e-9), gain, limit, 0.0)
    assert below == pytest.approx(above, rel=1e-6)
    errors = np.linspace(-4.0, 4.0, 401)
    out = np.array([sqrt_controller(e, gain, limit, 0.0) for e in errors])
    assert np.all(np.diff(out) > 0.0)
    for e, o in zip(errors[::20], out[::20], strict=True):
        assert inverse_sqrt_controller(o, gain, limit) == pytest.approx(e, abs=1e-9)
    # A step of dt never overshoots the error.
    assert abs(sqrt_controller(0.01, gain, limit, 0.1)) <= 0.01 / 0.1 + 1e-12


@pytest.mark.parametrize("jerk, accel", [(5.0, 2.5), (2.0, 1.0)])
def test_position_step_obeys_the_jerk_and_acceleration_limits(sitl_quad, jerk, accel):
    """A 3 m step: the shaped target changes its acceleration at most at PSC_JERK_XY,
    accelerates at most at WPNAV_ACCEL and arrives (ArduPilot's square-root shaping
    overshoots a little: under 5 % here); the vehicle follows."""
    loop = AutopilotLoop.from_parameters("ardupilot", {"PSC_JERK_XY": jerk,
                                                       "WPNAV_ACCEL": 100 * accel})
    step = Step((0.0, 0.0, 1.5, 0.0), (3.0, 0.0, 1.5, 0.0), duration=10.0)
    dt = 1.0 / loop.loop_rate
    flight = fly(loop, step, sitl_quad, sample_step=dt)
    x = flight.desired_position[:, 0]
    v = np.diff(x) / dt
    a = np.diff(v) / dt
    j = np.diff(a) / dt
    assert np.max(np.abs(a)) <= accel * 1.01
    assert np.max(np.abs(a)) >= 0.9 * accel       # the limit is reached, not just respected
    assert np.max(np.abs(j)) <= jerk * 1.01
    assert np.max(x) <= 3.0 * 1.05
    assert x[-1] == pytest.approx(3.0, abs=0.01)
    assert flight.position[-1, 0] == pytest.approx(3.0, abs=0.05)
    assert np.max(np.abs(flight.position[:, 1:] - [0.0, 1.5])) < 0.05


def test_yaw_step_obeys_the_slew_and_yaw_acceleration_limits(sitl_quad):
    """A 90° heading step: the attitude target turns at most at ATC_SLEW_YAW with its
    angular acceleration at most ATC_ACCEL_Y_MAX; the vehicle's yaw follows."""
    loop = AutopilotLoop.from_parameters("ardupilot", {"ATC_SLEW_YAW": 4500.0,
                                                       "ATC_ACCEL_Y_MAX": 9000.0})
    step = Step((0.0, 0.0, 1.5, 0.0), (0.0, 0.0, 1.5, math.pi / 2), duration=8.0)
    dt = 1.0 / loop.loop_rate
    flight = fly(loop, step, sitl_quad, sample_step=dt)
    w, x, y, z = flight.attitude_target.T
    target_yaw = np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    rate = np.diff(target_yaw) / dt
    assert np.max(np.abs(rate)) <= math.radians(45.0) * 1.01
    assert np.max(np.abs(rate)) >= math.radians(45.0) * 0.95
    assert np.max(np.abs(np.diff(rate) / dt)) <= math.radians(90.0) * 1.05
    assert flight.yaw[-1] == pytest.approx(math.pi / 2, abs=math.radians(2.0))
    assert np.max(flight.yaw) <= math.pi / 2 + math.radians(5.0)


def test_hover_stays_put(sitl_quad):
    """On a constant setpoint the loop holds it: no drift, hover rotor speeds."""
    loop = AutopilotLoop.from_parameters("ardupilot")
    hold = Step((0.5, -0.5, 1.5, 0.3), (0.5, -0.5, 1.5, 0.3), duration=5.0)
    flight = fly(loop, hold, sitl_quad, sample_step=0.01)
    assert np.max(np.abs(flight.position - [0.5, -0.5, 1.5])) < 1e-6
    assert np.allclose(flight.thrust, sitl_quad.mass * GRAVITY, rtol=1e-6)
    hover = math.sqrt(sitl_quad.mass * GRAVITY / 4 / sitl_quad.theta[0])
    assert np.allclose(flight.rotor_speeds, hover, rtol=1e-5)


def test_agrees_with_the_simulated_vehicle_where_both_track(sitl_quad):
    """Where ArduCopter's loop is as quick as the offline simulator's controller (input
    shaping at 20 ms, a stiff yaw-rate loop, the limits `mavsysid sim` reports) and the
    simulator's drag compensation has nothing to do (c_D = 0), both fly a figure alike: to
    a few cm and about a degree of yaw."""
    vehicle = replace(sitl_quad, parameters=replace(sitl_quad.parameters, c_D=0.0))
    figure = excitation_trajectory(ExcitationSpec(duration=16.0, amplitude=(0.6, 0.4, 0.2)))
    quick = {**SIM_LIMITS, "ATC_INPUT_TC": 0.02, "ATC_RAT_YAW_P": 1.0, "ATC_RAT_YAW_I": 0.2,
             "ATC_RAT_YAW_FLTE": 0.0}
    flight = fly(AutopilotLoop.from_parameters("ardupilot", quick), figure, vehicle,
                 sample_step=0.01)
    sim = Simulator(vehicle, settings=SimulationSettings(log_rate=100.0)).run(figure)
    t = np.clip(sim.times, 0.0, figure.duration)
    model = np.array([np.interp(t, flight.times, flight.position[:, i]) for i in range(3)]).T
    assert np.max(np.linalg.norm(model - sim.states[:, 0:3], axis=1)) < 0.04
    w, x, y, z = sim.states[:, 6:10].T
    sim_yaw = np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    model_yaw = np.interp(t, flight.times, flight.yaw)
    assert np.max(np.abs(sim_yaw - model_yaw)) < math.radians(1.0)
    # ArduCopter's stock input shaping and yaw-rate loop lag: there they part.
    stock = fly(AutopilotLoop.from_parameters("ardupilot", SIM_LIMITS), figure, vehicle,
                sample_step=0.01)
    stock_yaw = np.interp(t, stock.times, stock.yaw)
    assert np.max(np.abs(sim_yaw - stock_yaw)) > math.radians(3.0)


def test_limits_bind_where_the_simulated_vehicle_has_none(sitl_quad):
    """A figure just beyond ArduCopter's stock horizontal jerk (5.2 > 5 m/s³): the shaped
    target leaves the setpoints where the exact-tracking assumption sees nothing; with the
    limits `mavsysid sim` reports it stays on them."""
    figure = excitation_trajectory(ExcitationSpec(duration=10.0, amplitude=(0.6, 0.4, 0.2)))
    stock = fly(AutopilotLoop.from_parameters("ardupilot"), figure, sitl_quad, sample_step=0.01)
    free = fly(AutopilotLoop.from_parameters("ardupilot", SIM_LIMITS), figure, sitl_quad,
               sample_step=0.01)
    ref = figure.flat_outputs(stock.times).position
    off_stock = np.max(np.linalg.norm(stock.desired_position - ref, axis=1))
    off_free = np.max(np.linalg.norm(free.desired_position - ref, axis=1))
    assert off_free < 0.01
    assert off_stock > 3.0 * off_free


def test_parameters_and_derived_limits(sitl_quad):
    """Values read override the stock defaults (others ignored); the horizontal jerk is
    capped by the roll/pitch acceleration, ½ √(WPNAV_ACCEL · g · ATC_ACCEL_R_MAX)."""
    loop = AutopilotLoop.from_parameters("ardupilot", {"PSC_JERK_XY": 20.0, "NOT_A_PARAM": 1.0,
                                                       "ATC_ACCEL_R_MAX": 20000.0})
    assert loop.value("PSC_JERK_XY") == 20.0
    assert loop.value("WPNAV_ACCEL") == ARDUCOPTER_LOOP_DEFAULTS["WPNAV_ACCEL"]
    assert "NOT_A_PARAM" not in dict(loop.parameters)
    P = loop.kernel_parameters(sitl_quad, 0.0025)
    cap = 0.5 * math.sqrt(2.5 * GRAVITY * math.radians(200.0))
    assert P[arducopter_loop.P_JERK_XY] == pytest.approx(cap)


def test_torque_per_output_and_yaw_damping_of_the_sitl_quad(sitl_quad):
    """ArduPilot's mixer factors (±0.5) on SITL's X quad: roll 2 T_max · 0.2475 m, yaw
    2 T_max c_M/c_T; the rotor drag's yaw damping m c_D r² / j_z per T/m."""
    c_T, c_D, c_M = sitl_quad.theta[:3]
    t_max = c_T * sitl_quad.limits.rotor_speed_max**2
    per_unit = torque_per_output(sitl_quad)
    assert per_unit[0] == pytest.approx(2 * t_max * 0.24748737, rel=1e-6)
    assert per_unit[1] == pytest.approx(per_unit[0], rel=1e-9)
    assert per_unit[2] == pytest.approx(2 * t_max * c_M / c_T, rel=1e-6)
    r2 = 2 * 0.24748737**2
    assert yaw_damping(sitl_quad) == pytest.approx(sitl_quad.mass * c_D * r2 / sitl_quad.theta[5],
                                                   rel=1e-6)


def test_px4_loop_tilts_within_its_limit_and_arrives(sitl_quad):
    """PX4's offboard loop on a 4 m step (no shaping): the tilt reaches and keeps
    MPC_TILTMAX_AIR, the vehicle arrives and holds."""
    loop = AutopilotLoop.from_parameters("px4", {"MPC_TILTMAX_AIR": 20.0})
    step = Step((0.0, 0.0, 1.5, 0.0), (4.0, 0.0, 1.5, 0.0), duration=10.0)
    flight = fly(loop, step, sitl_quad, sample_step=0.005)
    x, y = flight.quaternion[:, 1], flight.quaternion[:, 2]
    tilt = np.degrees(np.arccos(np.clip(1 - 2 * (x * x + y * y), -1, 1)))
    assert np.max(tilt) <= 20.0 + 1.0
    assert np.max(tilt) >= 19.0
    assert flight.position[-1, 0] == pytest.approx(4.0, abs=0.05)


def test_px4_loop_holds_a_heading_of_half_a_turn(sitl_quad):
    """Hovering with the yaw setpoint at π: the attitude setpoint is the half turn about z
    (its quaternion taken from the largest diagonal term of the attitude matrix, where the
    trace alone leaves no scalar part), and the vehicle keeps that heading."""
    loop = AutopilotLoop.from_parameters("px4")
    hold = Step((0.0, 0.0, 1.5, math.pi), (0.0, 0.0, 1.5, math.pi), duration=2.0)
    flight = fly(loop, hold, sitl_quad, sample_step=0.01)
    assert np.max(np.abs(wrap_angle(flight.yaw - math.pi))) < 1e-9
    np.testing.assert_allclose(np.abs(flight.attitude_target[:, 3]), 1.0, atol=1e-12)
    assert np.max(np.abs(flight.position - [0.0, 0.0, 1.5])) < 1e-9
