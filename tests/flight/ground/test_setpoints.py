"""Tests of setpoint encoding (ENU → NED SET_POSITION_TARGET_LOCAL_NED) and the tick clock."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mavsysid.flight.ground.setpoints import (
    MAV_FRAME_LOCAL_NED,
    TYPE_MASK_FULL,
    Setpoint,
    SmoothMove,
    TickSchedule,
    trajectory_setpoint,
)
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.vehicle.frames import ned_to_enu, yaw_ned_to_enu


def _wire_roundtrip(setpoint: Setpoint):
    """The setpoint packed into a MAVLink 2 message and parsed back."""
    mavutil = load_mavutil()
    mav = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    f = setpoint.message_fields()
    msg = mav.set_position_target_local_ned_encode(
        1234, 1, 1, f["coordinate_frame"], f["type_mask"], f["x"], f["y"], f["z"], f["vx"],
        f["vy"], f["vz"], f["afx"], f["afy"], f["afz"], f["yaw"], f["yaw_rate"])
    parser = mavutil.mavlink.MAVLink(None)
    return parser.parse_char(msg.pack(mav))


def test_fields_are_ned_with_full_feed_forward():
    """ENU position/velocity/acceleration become NED (x↔y, −z); yaw π/2 − ψ; rate negated."""
    sp = Setpoint((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), (-1.0, 0.5, 2.0), yaw=0.25, yaw_rate=0.4)
    f = sp.message_fields()
    assert f["coordinate_frame"] == MAV_FRAME_LOCAL_NED == 1
    assert f["type_mask"] == TYPE_MASK_FULL == 0
    assert (f["x"], f["y"], f["z"]) == (2.0, 1.0, -3.0)
    assert (f["vx"], f["vy"], f["vz"]) == (0.2, 0.1, -0.3)
    assert (f["afx"], f["afy"], f["afz"]) == (0.5, -1.0, -2.0)
    assert f["yaw"] == pytest.approx(math.pi / 2 - 0.25)
    assert f["yaw_rate"] == pytest.approx(-0.4)


def test_yaw_is_wrapped_but_heading_preserved():
    """A continuous ENU yaw of several turns is sent as the same heading in (−π, π]."""
    sp = Setpoint((0.0, 0.0, 1.0), yaw=7.0)
    yaw = sp.message_fields()["yaw"]
    assert -math.pi <= yaw < math.pi
    assert math.cos(yaw) == pytest.approx(math.cos(math.pi / 2 - 7.0))
    assert math.sin(yaw) == pytest.approx(math.sin(math.pi / 2 - 7.0))


def test_wire_roundtrip_recovers_enu():
    """Packed and parsed by pymavlink, the NED fields convert back to the ENU setpoint."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        p, v, a = rng.normal(size=(3, 3))
        sp = Setpoint(tuple(p), tuple(v), tuple(a), float(rng.uniform(-3, 3)),
                      float(rng.normal()))
        msg = _wire_roundtrip(sp)
        assert msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
        assert msg.type_mask == 0 and msg.coordinate_frame == 1
        got = ned_to_enu(np.array([[msg.x, msg.y, msg.z], [msg.vx, msg.vy, msg.vz],
                                   [msg.afx, msg.afy, msg.afz]]))
        np.testing.assert_allclose(got, [p, v, a], atol=1e-6)
        d = yaw_ned_to_enu(msg.yaw) - sp.yaw
        assert abs(math.remainder(d, 2 * math.pi)) < 1e-6
        assert -msg.yaw_rate == pytest.approx(sp.yaw_rate, abs=1e-6)


def test_trajectory_setpoint_samples_flat_outputs():
    """The setpoint at t is the trajectory's flat output at t; held (at rest) outside."""
    traj = excitation_trajectory(ExcitationSpec(duration=12.0))
    for t in (0.0, 3.7, 8.25, 12.0):
        sp = trajectory_setpoint(traj, t)
        f = traj.flat_outputs(np.array([t]))
        np.testing.assert_allclose(sp.position, f.position[0])
        np.testing.assert_allclose(sp.velocity, f.velocity[0])
        np.testing.assert_allclose(sp.acceleration, f.acceleration[0])
        assert sp.yaw == pytest.approx(f.yaw[0]) and sp.t_traj == t
    late = trajectory_setpoint(traj, 15.0)
    assert late.t_traj == 12.0 and np.allclose(late.velocity, 0.0)


def test_smooth_move_is_rest_to_rest_within_speed():
    """The transfer starts and ends at rest at its poses, under the speed limit, yaw short way."""
    move = SmoothMove.between(np.array([0.0, 0.0, 0.3]), 3.0, np.array([2.0, -1.0, 1.5]),
                              -3.0, max_speed=0.8)
    start, end = move.setpoint(0.0), move.setpoint(move.duration)
    np.testing.assert_allclose(start.position, [0.0, 0.0, 0.3])
    np.testing.assert_allclose(end.position, [2.0, -1.0, 1.5])
    np.testing.assert_allclose([start.velocity, end.velocity, end.acceleration], 0.0,
                               atol=1e-12)
    assert end.yaw == pytest.approx(-3.0)
    # 3 → −3 rad is 0.28 rad the short way round, through π.
    assert abs(end.yaw - start.yaw) < 0.3
    t = np.linspace(0.0, move.duration, 400)
    speeds = [np.linalg.norm(move.setpoint(x).velocity) for x in t]
    assert max(speeds) <= 0.8 + 1e-9
    # Velocity is the derivative of position (consistent feed-forward).
    h = 1e-5
    mid = move.duration / 3
    fd = (np.array(move.setpoint(mid + h).position) - move.setpoint(mid - h).position) / (2 * h)
    np.testing.assert_allclose(fd, move.setpoint(mid).velocity, rtol=1e-5)


def test_schedule_is_drift_free():
    """Deadlines are start + k·T however late earlier ticks went out."""
    s = TickSchedule(start=10.0, period=0.02)
    assert s.due(9.99) is None
    assert s.due(10.0) == 0
    assert s.due(10.0001) is None
    assert s.due(10.0250) == 1  # 5 ms late
    assert s.deadline() == pytest.approx(10.04)  # not 10.045
    assert s.dropped == 0 and s.late == 1


def test_schedule_drops_missed_ticks():
    """A wake-up more than a period late sends the current tick and counts the skipped ones."""
    s = TickSchedule(start=0.0, period=0.02)
    assert s.due(0.0) == 0
    assert s.due(0.071) == 3  # ticks 1 and 2 missed
    assert s.dropped == 2 and s.sent == 2
    stats = s.statistics()
    assert stats["dropped"] == 2 and stats["sent"] == 2


def test_schedule_statistics_of_a_perfect_stream():
    """Sending exactly on the deadlines gives the nominal rate and zero deviation."""
    s = TickSchedule(start=1.0, period=0.02)
    for k in range(101):
        assert s.due(1.0 + k * 0.02 + 1e-12) == k
    stats = s.statistics()
    assert stats["rate_hz"] == pytest.approx(50.0)
    assert stats["period_deviation_p99_s"] < 1e-9
    assert stats["dropped"] == 0 and stats["late"] == 0

