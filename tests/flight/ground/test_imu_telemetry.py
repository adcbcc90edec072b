"""The streamer's IMU: the rate asked for, the samples taken from each autopilot's message,
and the pose log's IMU columns (FLU), decided once the telemetry streams."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.imu_telemetry import (
    IMU_MESSAGE_BYTES,
    MAX_IMU_RATE,
    SERIAL_SHARE,
    ImuTelemetry,
    imu_rate,
    request_imu,
)
from mavsysid.flight.ground.telemetry_recorder import SetpointHistory, TelemetryRecorder
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.formats.poselog import read_pose_log
from mavsysid.formats.tlog import STANDARD_GRAVITY

_ARDUPILOT, _PX4 = 3, 12


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


def _heartbeat(wire: _Wire, autopilot: int):
    return wire("heartbeat", 2, autopilot, 0, 0, 4)


def test_rate_is_what_the_link_carries() -> None:
    assert imu_rate("udp:127.0.0.1:14550", "RAW_IMU") == MAX_IMU_RATE
    assert imu_rate("tcp:127.0.0.1:5760", "HIGHRES_IMU") == MAX_IMU_RATE
    expected = SERIAL_SHARE * 57600 / 10.0 / IMU_MESSAGE_BYTES["RAW_IMU"]
    assert imu_rate("serial:/dev/ttyUSB0:57600", "RAW_IMU") == pytest.approx(expected)
    assert 30.0 < expected < 50.0  # a 57600 baud radio: a few tens of Hz
    assert imu_rate("/dev/ttyACM0:921600", "RAW_IMU") == MAX_IMU_RATE  # USB: all it sends
    assert imu_rate("/dev/ttyACM0:460800", "HIGHRES_IMU") < MAX_IMU_RATE
    asked = []

    def set_interval(name: str, rate: float) -> str | None:
        """Refuses any HIGHRES_IMU, and RAW_IMU faster than 100 Hz."""
        asked.append((name, rate))
        return None if name == "RAW_IMU" and rate <= 100.0 else "MAV_RESULT_DENIED"

    assert request_imu(set_interval, Autopilot.ARDUPILOT, "udp:127.0.0.1:1") == (
        "RAW_IMU", MAX_IMU_RATE / 4, None)
    assert [rate for _, rate in asked] == [MAX_IMU_RATE, MAX_IMU_RATE / 2, MAX_IMU_RATE / 4]
    asked.clear()
    assert request_imu(set_interval, Autopilot.PX4, "udp:127.0.0.1:1") == (
        "HIGHRES_IMU", 10.0, "MAV_RESULT_DENIED")
    assert [rate for _, rate in asked] == [320.0, 160.0, 80.0, 40.0, 20.0, 10.0]


def test_samples_of_each_message_in_flu(wire: _Wire) -> None:
    imu = ImuTelemetry()
    # RAW_IMU before an ArduPilot heartbeat is not known to be in mG: not read.
    raw = wire("raw_imu", 2_000_000, 100, -200, -1000, 10, 20, -30, 0, 0, 0, 0, 4500)
    assert imu.on_message(raw) and imu.latest is None
    assert not imu.on_message(_heartbeat(wire, _ARDUPILOT))
    imu.on_message(raw)
    s = imu.latest
    assert (s.t, s.message) == (2.0, "RAW_IMU")
    np.testing.assert_allclose(s.accel, np.array([0.1, 0.2, 1.0]) * STANDARD_GRAVITY)
    np.testing.assert_allclose(s.gyro, [0.010, -0.020, 0.030])
    imu.on_message(wire("scaled_imu", 2100, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0))
    np.testing.assert_allclose(imu.latest.accel, [0.0, 0.0, STANDARD_GRAVITY])
    imu.on_message(wire("highres_imu", 2_200_000, 0.5, 0.25, -9.0, 0.1, 0.2, 0.3, 0, 0, 0,
                        0, 0, 0, 20, 0b111111, 0))
    np.testing.assert_allclose(imu.latest.accel, [0.5, -0.25, 9.0])
    np.testing.assert_allclose(imu.latest.gyro, [0.1, -0.2, -0.3])
    # A partial update, a second IMU and a saturated reading are not taken.
    before = imu.latest
    imu.on_message(wire("highres_imu", 2_300_000, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 20,
                        0b000111, 0))
    imu.on_message(wire("highres_imu", 2_300_000, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 20,
                        0b111111, 1))
    imu.on_message(wire("scaled_imu", 2400, 32767, 0, 0, 0, 0, 0, 0, 0, 0, 0))
    assert imu.latest is before and imu.count == 3
    imu.on_message(_heartbeat(wire, _PX4))
    imu.on_message(raw)  # PX4's RAW_IMU holds raw counts
    assert imu.latest is before


def _feed(rec: TelemetryRecorder, wire: _Wire, ms: int, imu: bool) -> None:
    z4 = [0, 0, 0, 0]
    if imu:
        rec.on_message(wire("raw_imu", ms * 1000 - 500, 0, 0, -1000, ms, 0, 0, 0, 0, 0, 0, 0),
                       ms * 1e-3)
    rec.on_message(wire("attitude_quaternion", ms, 1.0, 0.0, 0.0, 0.0, 0, 0, 0, z4), ms * 1e-3)
    rec.on_message(wire("local_position_ned", ms, 1.0, 2.0, -3.0, 0.0, 0.0, 0.0), ms * 1e-3)


def test_rows_held_until_decided_then_written_with_the_imu(tmp_path, firefly, wire) -> None:
    rec = TelemetryRecorder(tmp_path / "pose.csv", firefly, SetpointHistory(), imu=None)
    rec.on_message(_heartbeat(wire, _ARDUPILOT), 0.0)
    _feed(rec, wire, 100, imu=False)  # before the IMU streams: left out
    for ms in (120, 140, 160):
        _feed(rec, wire, ms, imu=True)
    assert not (tmp_path / "pose.csv").exists() and rec.writes_imu is None
    rec.use_imu(True)
    _feed(rec, wire, 180, imu=True)
    log = read_pose_log(tmp_path / "pose.csv", 6)  # flushed: readable while open
    rec.close()
    np.testing.assert_allclose(log.t, [0.12, 0.14, 0.16, 0.18])
    np.testing.assert_allclose(log.gyro[:, 0], [0.12, 0.14, 0.16, 0.18])  # xgyro mrad/s
    np.testing.assert_allclose(log.accel, [[0.0, 0.0, STANDARD_GRAVITY]] * 4, atol=1e-6)
    assert rec.skipped["before the first IMU sample"] == 1
    summary = rec.imu_summary()
    assert summary["message"] == "RAW_IMU" and summary["rows"] == 4
    assert summary["lag_s"]["max"] == pytest.approx(0.0005)


def test_a_vehicle_without_imu_writes_every_row_without_it(tmp_path, firefly, wire) -> None:
    rec = TelemetryRecorder(tmp_path / "pose.csv", firefly, SetpointHistory(), imu=None)
    for ms in (100, 120):
        _feed(rec, wire, ms, imu=False)
    rec.close()  # never decided: written without the IMU
    log = read_pose_log(tmp_path / "pose.csv", 6)
    assert len(log) == 2 and log.gyro is None
