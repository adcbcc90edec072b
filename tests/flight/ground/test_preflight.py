"""Tests of the streamer's pre-flight refusals and warnings."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.ground.mavlink_link import VehicleState
from mavsysid.flight.ground.preflight import (
    PreflightReport,
    check_airframe,
    check_box,
    check_health,
    check_plan,
    check_rates,
    check_takeoff_point,
)
from mavsysid.flight.ground.stream_session import load_plan
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError, JobFailedError

BOX = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)


@pytest.fixture(scope="module")
def figure():
    """A 12 s excitation figure: x ∈ [−1.3, 1.3], y ∈ [−1, 1], z ∈ [1.1, 1.9] m."""
    return excitation_trajectory(ExcitationSpec(duration=12.0))


def _sys_status(present: int, enabled: int, health: int, battery: int = 80):
    mavlink = load_mavutil().mavlink
    return mavlink.MAVLink_sys_status_message(present, enabled, health, 500, 12000, 100,
                                              battery, 0, 0, 0, 0, 0, 0)


def test_trajectory_inside_the_box_passes(figure, firefly):
    """Every 100 Hz sample inside: no refusal."""
    assert check_box(figure, BOX) == []
    assert check_plan(figure, "firefly", firefly, BOX).refusals == ()


def test_excursion_is_refused_with_time_and_axis(figure):
    """A box 10 cm too low names z, the first sample outside and the farthest excursion."""
    (reason,) = check_box(figure, (-2.0, -2.0, 0.5, 2.0, 2.0, 1.8))
    assert "z = 1.9" in reason and "z_max 1.8 m" in reason
    assert "0.100 m outside" in reason
    t_first = float(reason.split("at t = ")[1].split(" s")[0])
    assert t_first == pytest.approx(0.0)  # the figure starts at its top corner


def test_excursion_between_knots_is_found():
    """A sample between segment knots that pokes out of the box is caught at 100 Hz."""
    traj = excitation_trajectory(ExcitationSpec(duration=12.0))
    t = np.arange(0, 1201) / 100.0
    x_min = traj.flat_outputs(t).position[:, 0].min()
    (reason,) = check_box(traj, (x_min + 0.005, -2.0, 0.5, 2.0, 2.0, 2.5))
    assert "x_min" in reason


def test_other_vehicle_is_refused(figure, firefly):
    """A trajectory planned for another vehicle is refused, naming both."""
    report = check_plan(figure, "quad_x", firefly, BOX)
    assert report.refusals and "'quad_x'" in report.refusals[0]
    with pytest.raises(JobFailedError, match="flight refused: the trajectory was made for"):
        report.raise_if_refused()


def test_airframe_rotor_count(firefly):
    """A QUADROTOR heartbeat for a hexacopter config is refused; HEXAROTOR passes."""
    assert check_airframe(firefly, 13) == []
    assert check_airframe(firefly, 99) == []  # not a multirotor type: not judged
    (reason,) = check_airframe(firefly, 2, "QUADROTOR")
    assert "QUADROTOR (4 rotors)" in reason and "has 6" in reason


def test_health_refusals():
    """Armed, critical, an unhealthy enabled sensor or a low battery refuse the flight."""
    ok = VehicleState(system=1, base_mode=1, system_status=3)
    assert check_health(ok, _sys_status(0b111, 0b111, 0b111)).refusals == ()
    names = {1: "MAV_SYS_STATUS_SENSOR_3D_GYRO", 4: "MAV_SYS_STATUS_SENSOR_3D_MAG"}
    bad = check_health(ok, _sys_status(0b111, 0b111, 0b011), names)
    assert bad.refusals == ("unhealthy sensors: 3D_MAG",)
    # A sensor that is present but disabled does not count.
    assert check_health(ok, _sys_status(0b111, 0b011, 0b011)).refusals == ()
    armed = VehicleState(system=1, base_mode=1 | 128, system_status=5)
    refusals = check_health(armed, _sys_status(1, 1, 1, battery=12)).refusals
    assert any("already armed" in r for r in refusals)
    assert any("MAV_STATE_CRITICAL" in r for r in refusals)
    assert any("battery at 12 %" in r for r in refusals)
    unknown = check_health(ok, None)
    assert unknown.refusals == () and "health not checked" in unknown.warnings[0]


def test_rates_warn_and_refuse():
    """Slow estimator telemetry warns; a pose too slow to watch tracking refuses."""
    good = {"LOCAL_POSITION_NED": 50.1, "ATTITUDE_QUATERNION": 49.8,
            "ESC_TELEMETRY_1_TO_4": 50.0, "ESC_TELEMETRY_5_TO_8": 50.0}
    assert check_rates(good, 50.0, 6) == PreflightReport()
    slow = {**good, "ESC_TELEMETRY_5_TO_8": 4.0}
    report = check_rates(slow, 50.0, 6)
    assert report.refusals == () and "ESC_TELEMETRY_5_TO_8 4.0 Hz" in report.warnings[0]
    assert check_rates(slow, 50.0, 4).warnings == ()  # a quad needs no 5_TO_8
    report = check_rates({"LOCAL_POSITION_NED": 3.0}, 50.0, 4)
    assert "cannot watch the tracking error" in report.refusals[0]


def test_missing_esc_rpm_with_motor_outputs_says_where_the_speeds_come_from():
    """No ESC rpm but SERVO_OUTPUT_RAW at the rate: one note naming the motor outputs and
    the [motor] curve, not "less information"; without the outputs, the slow-rate warning."""
    pose = {"LOCAL_POSITION_NED": 50.0, "ATTITUDE_QUATERNION": 50.0}
    report = check_rates({**pose, "SERVO_OUTPUT_RAW": 49.9}, 50.0, 4)
    assert report.refusals == () and len(report.warnings) == 1
    assert "SERVO_OUTPUT_RAW 49.9 Hz" in report.warnings[0]
    assert "[motor] curve" in report.warnings[0]
    assert "ESC_TELEMETRY_1_TO_4 0.0 Hz" in report.warnings[0]
    report = check_rates(pose, 50.0, 4)
    assert len(report.warnings) == 1 and "less information" in report.warnings[0]


def test_load_plan_refuses_before_connecting(tmp_path, firefly, figure):
    """load_plan: the embedded vehicle by default; no box is bad input; a bad box refuses."""
    path = tmp_path / "figure.json"
    write_trajectory_file(path, trajectory_file_for(figure, firefly, box=None))
    with pytest.raises(InputError, match="no flight box"):
        load_plan(path, None, None)
    _, config, box = load_plan(path, None, BOX)
    assert config.name == "firefly" and "embedded" in config.source and box == BOX
    with pytest.raises(JobFailedError, match="flight refused: the trajectory leaves the box"):
        load_plan(path, None, (-1.0, -1.0, 0.5, 1.0, 1.0, 2.5))
    with pytest.raises(JobFailedError, match="made for vehicle 'firefly', not 'quad_x'"):
        load_plan(path, "quad_x", BOX)
    with pytest.raises(InputError, match="min below its max"):
        load_plan(path, None, (1.0, -1.0, 0.5, -1.0, 1.0, 2.5))
    assert load_vehicle("quad_x").name == "quad_x"


def test_takeoff_point_under_the_box():
    """Taking off under the box passes; beside it is refused with the position."""
    assert check_takeoff_point((0.0, 0.0, 0.0), BOX) == []
    assert check_takeoff_point((2.0, -2.0, 0.0), BOX) == []  # on the edge
    (reason,) = check_takeoff_point((3.0, 0.5, 0.0), BOX)
    assert "x = 3.00 m, y = 0.50 m, outside the box's footprint [-2, 2] x [-2, 2] m" in reason
