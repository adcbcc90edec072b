"""Planning on the flight the autopilot is predicted to fly (`PlannerSettings.autopilot`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import kinematic_limits
from mavsysid.formats.parameter_file import read_parameter_file
from mavsysid.planner.belief import edge_samples, propagate_steps
from mavsysid.planner.feasibility import check_segment, rotor_square_range
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.rrbt import plan
from mavsysid.planner.search_setup import initial_covariance, segment_trajectory
from mavsysid.planner.segments import VertexState, connect_fixed
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.autopilot_loop import AutopilotLoop, fly
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.linearization import ErrorStateModel

STOCK = Path(__file__).resolve().parents[2] / "bench" / "arducopter_stock_limits.parm"


@pytest.fixture(scope="module")
def stock():
    """ArduCopter's stock limits and loop (SITL's copter.parm yaw-rate gains)."""
    values = read_parameter_file(STOCK)
    loop = AutopilotLoop.from_parameters("ardupilot", {**values, "ATC_RAT_YAW_P": 0.3,
                                                       "ATC_RAT_YAW_I": 0.02,
                                                       "MOT_THST_HOVER": 0.39})
    return kinematic_limits(Autopilot.ARDUPILOT, values), loop


@pytest.fixture(scope="module")
def planned(stock):
    """A sample-budgeted plan for the SITL quad on the stock loop, and its settings."""
    limits, loop = stock
    settings = PlannerSettings(budget=12.0, planning_time=np.inf, max_samples=80, seed=4,
                               refine_steps=60, autopilot_limits=limits, autopilot=loop)
    config = load_vehicle("sitl_quad")
    return config, settings, plan(config, settings)


def test_predicted_sigma_is_the_filter_on_the_predicted_flight(planned):
    """The plan's σ over time is the EKF recursion along the flight the loop is predicted
    to fly from the plan's setpoints (not along the setpoints)."""
    config, settings, result = planned
    model = ErrorStateModel.for_vehicle(config)
    states, n, dt = edge_samples(result.trajectory, config, config.theta,
                                 settings.measurement_rate, settings.autopilot)
    sigma0 = initial_covariance(model, config, settings)
    history = propagate_steps(model, sigma0, states, n, config.theta, dt)
    final = np.sqrt(np.diag(model.parameter_covariance_si(history[-1])))
    np.testing.assert_allclose(result.predicted_sigma[-1], final, rtol=1e-9)
    flat_states, flat_n, _ = edge_samples(result.trajectory, config, config.theta,
                                          settings.measurement_rate)
    exact = propagate_steps(model, sigma0, flat_states, flat_n, config.theta, dt)[-1]
    assert not np.allclose(np.sqrt(np.diag(model.parameter_covariance_si(exact))), final,
                           rtol=1e-3)


def test_the_predicted_flight_keeps_the_rotor_range(planned):
    """The whole predicted flight (continuous, not segment by segment) stays within the
    rotor range the search checked each segment's predicted flight against, to 2 %."""
    config, settings, result = planned
    flight = fly(settings.autopilot, result.trajectory, config, sample_step=0.005)
    lo, hi = rotor_square_range(config, settings.rotor_headroom)
    n2 = flight.rotor_speeds_squared
    assert n2.min() >= lo - 0.02 * (hi - lo) and n2.max() <= hi + 0.02 * (hi - lo)


def test_the_model_changes_the_plan(planned):
    """The same seed and budget with exact tracking plans another flight."""
    config, settings, result = planned
    exact = plan(config, replace(settings, autopilot=None))
    assert not (exact.trajectory.durations.shape == result.trajectory.durations.shape
                and np.allclose(exact.trajectory.durations, result.trajectory.durations))


def test_a_segment_the_loop_flies_beyond_the_rotors_is_refused(stock):
    """A fast segment within the rotor range as set (flatness) whose predicted flight
    (ArduCopter's lag and overshoot) needs more: refused as "autopilot rotor speed" once
    the top rotor speed lies between the two; with exact tracking it passes."""
    _, loop = stock
    sitl = load_vehicle("sitl_quad")
    a = VertexState.hover(np.array([-1.0, 0.0, 1.5]), 0.0)
    b = VertexState.hover(np.array([1.0, 0.0, 1.5]), 1.0)
    segment = connect_fixed(a, b, 2.2)
    flat = flat_to_state(segment.flat_outputs(np.linspace(0, 2.2, 441)), sitl)
    flown = fly(loop, segment, sitl, sample_step=0.04).rotor_speeds_squared
    set_top, flown_top = flat.rotor_speeds_squared.max(), flown.max()
    assert flown_top > 1.01 * set_top
    config = replace(sitl, limits=replace(sitl.limits, rotor_speed_max=float(
        np.sqrt(0.5 * (set_top + flown_top)))))
    box = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)
    assert check_segment(segment, config, np.array(box)).feasible
    settings = PlannerSettings(budget=12.0, box=box, autopilot=loop)
    assert GraphSearch(config, settings, "dopt", None).refusal(segment) == \
        "autopilot rotor speed"
    exact = replace(settings, autopilot=None)
    assert GraphSearch(config, exact, "dopt", None).refusal(segment) == ""
    samples = GraphSearch(config, settings, "dopt", None).samples_of(segment)
    reference = edge_samples(segment_trajectory(segment), config, config.theta,
                             settings.propagation_rate, loop)
    np.testing.assert_allclose(samples[1], reference[1])
