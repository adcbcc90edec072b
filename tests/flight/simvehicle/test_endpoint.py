"""Tests of the simulated vehicle's MAVLink interface, with a real pymavlink ground station
over 127.0.0.1 (UDP, and TCP once): heartbeat, telemetry rates, requests, parameters,
signing."""

from __future__ import annotations

import hashlib
import math
import struct
import time

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import PX4_MODES, Autopilot
from mavsysid.flight.simvehicle.link import mavlink as M

from tests.support.sim_gcs import running_sim

ACCEPTED = M.MAV_RESULT_ACCEPTED


def _rate(messages) -> float:
    """Messages per second of sim time (time_boot_ms, or the time of the message before)."""
    t = np.array([m.sim_time for m in messages])
    return (t.size - 1) / (t[-1] - t[0])


@pytest.mark.parametrize(("vehicle", "mav_type"), [("firefly", M.MAV_TYPE_HEXAROTOR),
                                                   ("quad_x", M.MAV_TYPE_QUADROTOR)])
def test_heartbeat_identifies_an_ardupilot_copter(vehicle, mav_type):
    """HEARTBEAT at 1 Hz from 1/1: ArduPilot, the frame's MAV_TYPE, STABILIZE, disarmed, v2."""
    with running_sim(vehicle) as (_, gcs):
        beats = gcs.collect("HEARTBEAT", 3.0)
        hb = beats[-1]
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        assert hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert hb.type == mav_type
        assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        assert hb.custom_mode == 0  # STABILIZE
        assert hb.system_status == M.MAV_STATE_STANDBY
        assert hb.get_msgbuf()[0] == 253  # MAVLink 2
        assert 2 <= len(beats) <= 4


def test_px4_heartbeat_and_bytewise_parameters():
    """--autopilot px4: autopilot 12, Hold's custom_mode; integer parameters sent bytewise."""
    with running_sim(autopilot=Autopilot.PX4) as (_, gcs):
        hb = gcs.recv("HEARTBEAT")
        assert hb.autopilot == M.MAV_AUTOPILOT_PX4
        assert hb.custom_mode == PX4_MODES["HOLD"]
        gcs.link.mav.param_request_read_send(1, 1, b"MAV_SYS_ID", -1)
        value = gcs.recv("PARAM_VALUE", condition=lambda m: m.param_id == "MAV_SYS_ID")
        assert value.param_type == M.MAV_PARAM_TYPE_INT32
        assert struct.unpack("<i", struct.pack("<f", value.param_value))[0] == 1


def test_default_rates_then_set_message_interval_changes_the_achieved_rate():
    """ArduPilot-like default rates; SET_MESSAGE_INTERVAL sets rates achieved within 1 %."""
    kinds = ["ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT",
             "ESC_TELEMETRY_1_TO_4", "ESC_TELEMETRY_5_TO_8", "SYS_STATUS", "EKF_STATUS_REPORT"]
    with running_sim(ekf_delay=0.0, speedup=4.0) as (_, gcs):
        default = gcs.collect(kinds, 6.0)
        count = {k: sum(m.get_type() == k for m in default) for k in kinds}
        assert count["ATTITUDE_QUATERNION"] == 0
        assert count["ATTITUDE"] == pytest.approx(24, abs=2)
        assert count["LOCAL_POSITION_NED"] == pytest.approx(18, abs=2)
        assert count["ESC_TELEMETRY_1_TO_4"] == pytest.approx(6, abs=1)
        assert count["EKF_STATUS_REPORT"] == pytest.approx(6, abs=1)

        assert gcs.set_rate(M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, 100.0) == ACCEPTED
        assert gcs.set_rate(M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 50.0) == ACCEPTED
        assert gcs.set_rate(M.MAVLINK_MSG_ID_ESC_TELEMETRY_1_TO_4, 50.0) == ACCEPTED
        gcs.collect(kinds, 0.1)
        fast = gcs.collect(kinds, 3.0)
        by_kind = {k: [m for m in fast if m.get_type() == k] for k in kinds}
        assert _rate(by_kind["ATTITUDE_QUATERNION"]) == pytest.approx(100.0, rel=0.01)
        assert _rate(by_kind["LOCAL_POSITION_NED"]) == pytest.approx(50.0, rel=0.01)
        assert _rate(by_kind["ESC_TELEMETRY_1_TO_4"]) == pytest.approx(50.0, rel=0.01)
        assert _rate(by_kind["ESC_TELEMETRY_5_TO_8"]) == pytest.approx(50.0, rel=0.01)
        assert all(m.time_boot_ms % 20 == 0 for m in by_kind["LOCAL_POSITION_NED"])
        # Within a tick, the attitude and ESC rpm go out before LOCAL_POSITION_NED.
        seq = [m for m in fast if m.get_type() not in ("GLOBAL_POSITION_INT", "ATTITUDE")]
        checked = 0
        for i, m in enumerate(seq[3:], start=3):
            if m.get_type() == "LOCAL_POSITION_NED":
                before = seq[i - 3:i]
                assert [b.get_type() for b in before] == [
                    "ATTITUDE_QUATERNION", "ESC_TELEMETRY_1_TO_4", "ESC_TELEMETRY_5_TO_8"]
                assert before[0].time_boot_ms == m.time_boot_ms
                checked += 1
        assert checked >= 100

        gcs.link.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0,
                                       M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, 0, 0, 0, 0, 0, 0)
        reply = gcs.recv("MESSAGE_INTERVAL")
        assert reply.interval_us == 10000
        assert gcs.set_rate(M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, -1.0) == ACCEPTED
        gcs.collect(kinds, 0.1)
        assert not [m for m in gcs.collect(kinds, 1.0) if m.get_type() == "ATTITUDE_QUATERNION"]


def test_requested_messages_and_unknown_commands():
    """REQUEST_MESSAGE and REQUEST_AUTOPILOT_CAPABILITIES are ACKed and answered; unknown
    commands get UNSUPPORTED, unknown message ids FAILED."""
    with running_sim(ekf_delay=0.0) as (_, gcs):
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) \
            == ACCEPTED
        version = gcs.recv("AUTOPILOT_VERSION")
        assert version.capabilities & M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        assert version.capabilities & M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
        assert gcs.command(M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == ACCEPTED
        assert gcs.recv("AUTOPILOT_VERSION") is not None
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_SYS_STATUS) == ACCEPTED
        assert gcs.recv("SYS_STATUS") is not None
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, 12345) == M.MAV_RESULT_FAILED
        assert gcs.command(31010) == M.MAV_RESULT_UNSUPPORTED
        assert gcs.command(M.MAV_CMD_DO_SET_SERVO, 5, 1500) == M.MAV_RESULT_UNSUPPORTED


def test_position_and_home_wait_for_the_ekf():
    """Before --ekf-delay: no position messages, EKF flags without position, no home;
    afterwards all of them, and HOME_POSITION once unasked at the start position."""
    with running_sim(ekf_delay=2.0, start=(1.0, -2.0, 0.0)) as (_, gcs):
        early = gcs.collect(["LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "HOME_POSITION",
                             "EKF_STATUS_REPORT"], 1.5)
        assert {m.get_type() for m in early} == {"EKF_STATUS_REPORT"}
        assert not early[-1].flags & M.EKF_POS_HORIZ_ABS
        assert gcs.command(M.MAV_CMD_GET_HOME_POSITION) == M.MAV_RESULT_FAILED
        home = gcs.recv("HOME_POSITION", timeout=gcs.wall(2.0))
        assert (home.x, home.y, home.z) == pytest.approx((-2.0, 1.0, 0.0))
        ekf = gcs.recv("EKF_STATUS_REPORT", timeout=gcs.wall(1.5))
        needed = M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_POS_HORIZ_ABS | M.EKF_POS_VERT_ABS
        assert ekf.flags & needed == needed
        local = gcs.recv("LOCAL_POSITION_NED", timeout=gcs.wall(1.0))
        assert (local.x, local.y, local.z) == pytest.approx((-2.0, 1.0, 0.0), abs=0.005)
        glob = gcs.recv("GLOBAL_POSITION_INT", timeout=gcs.wall(1.0))
        assert glob.relative_alt == pytest.approx(0, abs=5)
        assert glob.alt == pytest.approx(488000, abs=5)
        assert gcs.command(M.MAV_CMD_GET_HOME_POSITION) == ACCEPTED
        assert gcs.recv("HOME_POSITION") is not None


def test_parameter_protocol():
    """PARAM_REQUEST_LIST: every parameter once with count and index; READ by name and
    index; SET of a known name echoes and acts, of an unknown one gets no answer."""
    with running_sim() as (endpoint, gcs):
        gcs.link.mav.param_request_list_send(1, 1)
        first = gcs.recv("PARAM_VALUE")
        values = [first] + [gcs.recv("PARAM_VALUE", timeout=1.0)
                            for _ in range(first.param_count - 1)]
        assert sorted(v.param_index for v in values) == list(range(first.param_count))
        names = {v.param_id: v for v in values}
        assert {"GUID_TIMEOUT", "WPNAV_SPEED", "ANGLE_MAX", "FRAME_CLASS", "SYSID_THISMAV",
                "DISARM_DELAY", "SR0_POSITION", "SR0_EXTRA1", "BATT_CAPACITY"} <= set(names)
        assert names["GUID_TIMEOUT"].param_value == pytest.approx(3.0)
        assert names["FRAME_CLASS"].param_value == 2  # hexa
        assert names["FRAME_CLASS"].param_type == M.MAV_PARAM_TYPE_INT8

        gcs.link.mav.param_request_read_send(1, 1, b"", names["WPNAV_SPEED"].param_index)
        assert gcs.recv("PARAM_VALUE").param_id == "WPNAV_SPEED"
        gcs.link.mav.param_set_send(1, 1, b"GUID_TIMEOUT", 1.5, M.MAV_PARAM_TYPE_REAL32)
        echo = gcs.recv("PARAM_VALUE")
        assert (echo.param_id, echo.param_value) == ("GUID_TIMEOUT", 1.5)
        assert endpoint.params["GUID_TIMEOUT"] == 1.5
        gcs.link.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, M.MAV_PARAM_TYPE_REAL32)
        gcs.link.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM2", -1)
        assert gcs.recv("PARAM_VALUE", timeout=1.0) is None
        # SR0_POSITION acts on the stream rate, as on ArduPilot.
        gcs.link.mav.param_set_send(1, 1, b"SR0_POSITION", 10.0, M.MAV_PARAM_TYPE_INT16)
        gcs.recv("PARAM_VALUE")
        endpoint.autopilot.ekf_delay = 0.0
        gcs.collect("LOCAL_POSITION_NED", 0.5)
        assert _rate(gcs.collect("LOCAL_POSITION_NED", 2.0)) == pytest.approx(10.0, rel=0.02)


def test_tcp_link_and_stream_requests():
    """Over tcpin the vehicle answers too; REQUEST_DATA_STREAM sets a stream group's rate."""
    with running_sim(transport="tcp", ekf_delay=0.0) as (_, gcs):
        assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) \
            == ACCEPTED
        gcs.link.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTRA1, 20, 1)
        gcs.collect("ATTITUDE", 0.3)
        assert _rate(gcs.collect("ATTITUDE", 2.0)) == pytest.approx(20.0, rel=0.02)


def _eventually(condition, timeout: float = 3.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "condition not met in time"
        time.sleep(0.01)


def _signing_link(link, key: bytes) -> None:
    link.setup_signing(key, sign_outgoing=True)


def test_signing_ignores_and_counts_unsigned_and_wrongly_signed_commands():
    """With a key, the vehicle signs what it sends; unsigned or wrongly signed commands and
    setpoints are ignored and counted; correctly signed ones are answered."""
    key = hashlib.sha256(b"correct horse").digest()
    with running_sim(signing_key=key) as (endpoint, gcs):
        hb = gcs.recv("HEARTBEAT")
        assert hb.get_msgbuf()[2] & M.MAVLINK_IFLAG_SIGNED
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=1.0) is None
        gcs.setpoint(z=-1.0)
        _eventually(lambda: endpoint.rejected()["setpoints"] == 1)
        rejected = endpoint.rejected()
        assert (rejected["commands"], rejected["setpoints"]) == (1, 1)
        assert rejected["unsigned"] >= 2 and rejected["bad_signature"] == 0
        assert not endpoint.autopilot.armed

        _signing_link(gcs.link, hashlib.sha256(b"wrong").digest())
        gcs.link.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0,
                                       0, 0, 0)
        _eventually(lambda: endpoint.rejected()["bad_signature"] >= 1)
        assert endpoint.rejected()["commands"] == 2

        _signing_link(gcs.link, key)
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
        assert endpoint.autopilot.armed
        assert endpoint.rejected()["commands"] == 2
        assert math.isfinite(endpoint.summary().clock.mean_tick_rate)
