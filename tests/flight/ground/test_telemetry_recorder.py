"""Tests of the streamer's pose log: rows from hand-packed MAVLink telemetry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mavsysid.flight.ground.setpoints import Setpoint
from mavsysid.flight.ground.telemetry_recorder import (
    ClockOffset,
    SetpointHistory,
    TelemetryRecorder,
)
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import euler_ned_to_quaternion, quaternion_ned_to_enu
from mavsysid.vehicle.rotation import quat_to_matrix


class _Wire:
    """Packs messages as the vehicle (system 1) would and parses them back."""

    def __init__(self) -> None:
        mavutil = load_mavutil()
        self.mav = mavutil.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = mavutil.mavlink.MAVLink(None)

    def __call__(self, name: str, *args):
        msg = getattr(self.mav, f"{name}_encode")(*args)
        return self.parser.parse_char(msg.pack(self.mav))


@pytest.fixture
def wire() -> _Wire:
    return _Wire()


def _quaternion_ned(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def test_rows_convert_pose_and_stamp_esc_with_the_next_position(tmp_path, firefly, wire):
    """One row per LOCAL_POSITION_NED: ENU pose, FLU attitude, the ESC rpm received before it."""
    rec = TelemetryRecorder(tmp_path / "pose.csv", firefly, SetpointHistory())
    rng = np.random.default_rng(0)
    q1, q2 = _quaternion_ned(rng), _quaternion_ned(rng)
    rpm_a, rpm_b, rpm_c = [4000, 4100, 4200, 4300], [4400, 4500, 0, 0], [5000, 5001, 5002, 5003]
    z4 = [0, 0, 0, 0]
    feed = [
        wire("attitude_quaternion", 100, *q1, 0, 0, 0, [0, 0, 0, 0]),
        wire("esc_telemetry_1_to_4", z4, z4, z4, z4, rpm_a, z4),
        wire("esc_telemetry_5_to_8", z4, z4, z4, z4, rpm_b, z4),
        wire("local_position_ned", 100, 1.0, 2.0, -3.0, 0.1, 0.2, -0.3),
        wire("attitude_quaternion", 102, *q2, 0, 0, 0, [0, 0, 0, 0]),
        wire("local_position_ned", 102, 1.5, 2.5, -3.5, 0.0, 0.0, 0.0),
        wire("esc_telemetry_1_to_4", z4, z4, z4, z4, rpm_c, z4),
        wire("local_position_ned", 104, 1.6, 2.6, -3.6, 0.0, 0.0, 0.0),
    ]
    for i, msg in enumerate(feed):
        rec.on_message(msg, 5.0 + 0.0005 * i)
    # Flushed per row: readable while the recorder is still open.
    log = read_pose_log(tmp_path / "pose.csv", 6)
    rec.close()
    np.testing.assert_allclose(log.t, [0.100, 0.102, 0.104])
    np.testing.assert_allclose(log.position[0], [2.0, 1.0, 3.0])
    np.testing.assert_allclose([log.extra[c][0] for c in ("vx", "vy", "vz")], [0.2, 0.1, 0.3])
    np.testing.assert_allclose(log.quaternion[0], quaternion_ned_to_enu(q1), atol=2e-7)
    np.testing.assert_allclose(log.quaternion[1], quaternion_ned_to_enu(q2), atol=2e-7)
    first = np.array(rpm_a + rpm_b[:2]) * RPM_TO_RAD_S
    np.testing.assert_allclose(log.rotor_speeds[0], first, atol=1e-4)
    np.testing.assert_allclose(log.rotor_speeds[1], first, atol=1e-4)  # no new ESC yet
    np.testing.assert_allclose(log.rotor_speeds[2, :4], np.array(rpm_c) * RPM_TO_RAD_S,
                               atol=1e-4)
    assert np.all(log.extra["ref_active"] == 0.0) and np.all(log.extra["t_traj"] == -1.0)


def test_attitude_euler_until_the_first_quaternion(tmp_path, firefly, wire):
    """Rows wait for an attitude; ATTITUDE serves until ATTITUDE_QUATERNION arrives."""
    rec = TelemetryRecorder(tmp_path / "pose.csv", firefly, SetpointHistory())
    roll, pitch, yaw = 0.1, -0.2, 2.5
    q = np.array([0.9, 0.1, 0.3, 0.2])
    q /= np.linalg.norm(q)
    feed = [
        wire("local_position_ned", 10, 0, 0, -1, 0, 0, 0),
        wire("attitude", 12, roll, pitch, yaw, 0, 0, 0),
        wire("local_position_ned", 12, 0, 0, -1, 0, 0, 0),
        wire("attitude_quaternion", 14, *q, 0, 0, 0, [0, 0, 0, 0]),
        wire("attitude", 16, 0.0, 0.0, 0.0, 0, 0, 0),  # ignored from now on
        wire("local_position_ned", 16, 0, 0, -1, 0, 0, 0),
        wire("local_position_ned", 16, 0, 0, -1, 0, 0, 0),  # repeated time
    ]
    for msg in feed:
        rec.on_message(msg, 1.0)
    rec.close()
    log = read_pose_log(tmp_path / "pose.csv", 6)
    assert rec.skipped == {"no attitude yet": 1, "time not increasing": 1}
    np.testing.assert_allclose(log.t, [0.012, 0.016])
    # The Euler quaternion is the Z-Y-X rotation: its matrix's yaw/pitch/roll match.
    R = quat_to_matrix(euler_ned_to_quaternion(roll, pitch, yaw))
    assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(yaw)
    assert -math.asin(R[2, 0]) == pytest.approx(pitch)
    assert math.atan2(R[2, 1], R[2, 2]) == pytest.approx(roll)
    np.testing.assert_allclose(log.quaternion[0],
                               quaternion_ned_to_enu(euler_ned_to_quaternion(roll, pitch, yaw)),
                               atol=1e-7)
    np.testing.assert_allclose(log.quaternion[1], quaternion_ned_to_enu(q), atol=2e-7)


def test_reference_is_the_target_in_effect_at_the_vehicle_time(tmp_path, firefly, wire):
    """Rows carry the last setpoint sent before their time mapped to the streamer's clock,
    advanced from its sample time to theirs along its velocity."""
    history = SetpointHistory()
    rec = TelemetryRecorder(tmp_path / "pose.csv", firefly, history)
    # Vehicle clock = streamer clock − 100 s; the fastest message took 1 ms.
    offset = 100.0
    q = [1.0, 0.0, 0.0, 0.0]
    att = wire("attitude_quaternion", 1000, *q, 0, 0, 0, [0, 0, 0, 0])
    rec.on_message(att, 1.0 + offset + 0.001)
    # Sampled on a 20 ms grid, the second sent 2 ms late.
    history.add(101.010, Setpoint((1.0, 2.0, 3.0), (1.0, 0.0, 0.0), yaw=0.5, t_traj=0.0),
                101.010)
    history.add(101.032, Setpoint((1.1, 2.0, 3.0), (1.0, 0.0, 0.0), yaw=0.6, t_traj=0.02),
                101.030)
    for ms, receipt in ((1005, 101.009), (1020, 101.025), (1040, 101.048)):
        rec.on_message(wire("local_position_ned", ms, 2.0, 1.0, -3.0, 0, 0, 0), receipt)
    history.add(101.045, None)  # streaming stopped
    rec.on_message(wire("local_position_ned", 1050, 2.0, 1.0, -3.0, 0, 0, 0), 101.052)
    rec.close()
    log = read_pose_log(tmp_path / "pose.csv", 6)
    np.testing.assert_allclose(log.extra["ref_active"], [0, 1, 1, 0])
    # Row times map to 101.006, 101.021, 101.041, 101.051 on the streamer's clock.
    np.testing.assert_allclose(log.extra["x_ref"][1:3], [1.011, 1.111])
    np.testing.assert_allclose(log.extra["yaw_ref"][1:3], [0.5, 0.6])
    np.testing.assert_allclose(log.extra["t_traj"], [-1, 0.011, 0.031, -1])
    assert rec.offset.value == pytest.approx(offset + 0.001)
    summary = rec.tracking_summary()
    assert summary["rows"] == 2
    assert summary["max_m"] == pytest.approx(0.111)
    assert rec.latest is not None and rec.latest.tracking_error is None


def test_clock_offset_is_a_sliding_minimum():
    """The offset is the least receipt − stamp lately, and follows a drifting clock."""
    off = ClockOffset(window=1.0)
    assert off.value is None
    for i in range(10):
        t = 0.1 * i
        off.add(t + 0.003 + 0.002 * (i % 3), t)
    assert off.value == pytest.approx(0.003)
    for i in range(30):  # the vehicle clock now lags 50 ms more
        t = 1.0 + 0.1 * i
        off.add(t + 0.053, t)
    assert off.value == pytest.approx(0.053)


def test_history_lookup():
    """The target is the last setpoint sent at or before the time, advanced from its sample
    time; None before any and after a stop."""
    h = SetpointHistory(keep=1.0)
    a = Setpoint((0.0, 0.0, 1.0), (0.5, 0.0, 0.0), (0.0, 0.0, 2.0), yaw=1.0, yaw_rate=-1.0)
    b = Setpoint((1.0, 0.0, 1.0))
    assert h.at(5.0) is None
    h.add(1.0, a, 0.99)
    h.add(2.0, b)
    assert h.at(0.5) is None and h.at(2.0) == b and h.at(7.0).position == b.position
    mid = h.at(1.5)
    np.testing.assert_allclose(mid.position, [0.255, 0.0, 1.0 + 0.51**2])
    np.testing.assert_allclose(mid.velocity, [0.5, 0.0, 1.02])
    assert mid.yaw == pytest.approx(0.49) and mid.t_traj == -1.0
    h.add(3.5, None)
    assert h.at(4.0) is None and h.last is None
