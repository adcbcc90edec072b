"""Round trips of MAVLink telemetry logs (written with pymavlink) through load_flight."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import LogFormatError

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]

BOOT = 10.0  # s since boot at the first sample
EPOCH = 1.7e9  # s, the ground station's clock at boot
LATENCY = 0.004  # s, link latency of every message
AUTOPILOT = (1, 1)
MOCAP = (255, 190)


def _flight(truth: Truth, vehicle: VehicleConfig, pose: str, rotors: str,
            hold: float = 0.0) -> list[Any]:
    """Records of a 4 s flight: HEARTBEAT, pose messages and rotor messages; the autopilot's
    clock stopped for ``hold`` s of receipt time 0.5 s into it (a lock-stepped simulator
    waiting for its peer)."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    records: list[Any] = []

    def receipt(t: float) -> float:
        return EPOCH + t + LATENCY + (hold if t > BOOT + 0.5 else 0.0)

    records.append((receipt(BOOT - 0.5), m.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3),
                    AUTOPILOT))
    t_pos = BOOT + np.arange(200) / 50.0
    x = truth(t_pos)
    for t, p in zip(t_pos, x["position_ned"], strict=True):
        msg = m.MAVLink_local_position_ned_message(round(t * 1e3), *p, 0.0, 0.0, 0.0)
        records.append((receipt(t), msg, AUTOPILOT))
    t_att = t_pos + 0.01
    for t, q in zip(t_att, truth(t_att)["quaternion_ned"], strict=True):
        if pose == "euler":
            w, x_, y, z = q
            msg = m.MAVLink_attitude_message(
                round(t * 1e3), np.arctan2(2 * (w * x_ + y * z), 1 - 2 * (x_ * x_ + y * y)),
                np.arcsin(2 * (w * y - z * x_)),
                np.arctan2(2 * (w * z + x_ * y), 1 - 2 * (y * y + z * z)), 0.0, 0.0, 0.0)
        else:
            msg = m.MAVLink_attitude_quaternion_message(round(t * 1e3), *q, 0.0, 0.0, 0.0,
                                                        [0.0] * 4)
        records.append((receipt(t), msg, AUTOPILOT))
    if pose == "mocap":
        t_mocap = BOOT + np.arange(400) / 100.0
        x = truth(t_mocap)
        for t, p, q in zip(t_mocap, x["position_ned"], x["quaternion_ned"], strict=True):
            msg = m.MAVLink_att_pos_mocap_message(round(t * 1e6), list(q), *p, [0.0] * 21)
            records.append((receipt(t), msg, MOCAP))
    t_rot = BOOT + 0.005 + np.arange(199) / 50.0
    n = truth(t_rot)["rotor_speeds"]
    for t, row in zip(t_rot, n, strict=True):
        if rotors == "esc":
            rpm = [round(v * 60.0 / (2.0 * np.pi)) for v in row] + [0, 0]
            for cls, part in ((m.MAVLink_esc_telemetry_1_to_4_message, rpm[:4]),
                              (m.MAVLink_esc_telemetry_5_to_8_message, rpm[4:])):
                records.append((receipt(t), cls([0] * 4, [0] * 4, [0] * 4, [0] * 4, part,
                                                [0] * 4), AUTOPILOT))
        elif rotors == "servo":
            e = vehicle.motor.thrust_expo
            s = (row / vehicle.limits.rotor_speed_max) ** 2
            u = (-(1 - e) + np.sqrt((1 - e) ** 2 + 4 * e * s)) / (2 * e)
            pwm = [round(1000 + 1000 * v) for v in u] + [1500, 0]  # channel 7: a servo
            msg = m.MAVLink_servo_output_raw_message(round(t * 1e6), 0, *pwm)
            records.append((receipt(t), msg, AUTOPILOT))
    return records


@pytest.mark.parametrize(
    ("pose", "rotors", "pose_source", "rotor_atol"),
    [
        ("autopilot", "esc", "autopilot", 0.1),  # integer rpm: ±0.05 rad/s
        ("mocap", "esc", "motion_capture", 0.1),
        ("autopilot", "servo", "autopilot", 0.5),  # integer µs: ±0.35 rad/s
        ("euler", "esc", "autopilot", 0.1),  # ATTITUDE instead of ATTITUDE_QUATERNION
    ],
)
def test_tlog_round_trip(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                         tlog_writer: Callable[..., None],
                         assert_matches_truth: Callable[..., None], pose: str, rotors: str,
                         pose_source: str, rotor_atol: float) -> None:
    """A NED/FRD tlog reads back in ENU/FLU, rad/s, on the autopilot's clock."""
    path = tmp_path / "flight.tlog"
    tlog_writer(path, _flight(truth, firefly, pose, rotors))
    data = load_flight(path, firefly)
    assert data.pose_source == pose_source
    assert data.rotor_count == 6
    # Receipt-stamped messages land on the autopilot clock: t is s since boot.
    assert BOOT <= data.t[0] < BOOT + 0.03
    assert data.t[-1] == pytest.approx(BOOT + 3.98, abs=0.03)
    rate = 100.0 if pose == "mocap" else 50.0
    np.testing.assert_allclose(np.diff(data.t), 1.0 / rate, atol=1e-6)
    # Attitude at 50 Hz, 10 ms off the position samples: slerp error ≤ |ω̇| dt²/8 ≈ 6e-5.
    assert_matches_truth(data, truth, rotor_atol, pose_atol=1e-4)
    assert any("SERVO_OUTPUT_RAW" in w for w in data.warnings) == (rotors == "servo")


def test_tlog_without_rotor_information_names_the_file(tmp_path: Path, firefly: VehicleConfig,
                                                       truth: Truth,
                                                       tlog_writer: Callable[..., None]) -> None:
    """A tlog with pose but neither ESC rpm nor servo outputs is a one-line error."""
    path = tmp_path / "flight.tlog"
    tlog_writer(path, _flight(truth, firefly, "autopilot", "none"))
    with pytest.raises(LogFormatError) as info:
        load_flight(path, firefly)
    message = str(info.value)
    assert message.count(str(path)) == 2 and "\n" not in message
    assert "no rotor speeds or motor outputs in" in message


def test_a_stopped_autopilot_clock_keeps_the_esc_rpm_in_place(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth, tlog_writer: Callable[..., None],
        assert_matches_truth: Callable[..., None]) -> None:
    """ESC rpm carries no autopilot time: stamped from its receipt, it stays on the
    autopilot's clock where that clock stood still for 30 s of receipt time."""
    path = tmp_path / "flight.tlog"
    tlog_writer(path, _flight(truth, firefly, "autopilot", "esc", hold=30.0))
    data = load_flight(path, firefly)
    assert data.t[-1] == pytest.approx(BOOT + 3.98, abs=0.03)
    assert_matches_truth(data, truth, 0.1, pose_atol=1e-4)


def _sagging_battery(start: float, end: float) -> list[Any]:
    """SYS_STATUS at 2 Hz over the 4 s flight, the battery falling linearly start → end V."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    records = []
    for t in BOOT + np.arange(9) / 2.0:
        volts = start + (end - start) * (t - BOOT) / 4.0
        msg = m.MAVLink_sys_status_message(0, 0, 0, 500, round(volts * 1000), 3000, 50,
                                           0, 0, 0, 0, 0, 0)
        records.append((EPOCH + t + LATENCY, msg, AUTOPILOT))
    return records


def test_commanded_rotor_speeds_follow_the_battery_voltage(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth,
        tlog_writer: Callable[..., None]) -> None:
    """Servo outputs with the battery falling 16.8 → 14.0 V: with [motor] voltage 16.8 the
    rotor speeds are the curve's times V/16.8 (a motor turns as fast as its supply lets);
    without it they are the curve's, and a note says how far the battery fell."""
    import dataclasses

    path = tmp_path / "flight.tlog"
    tlog_writer(path, sorted(_flight(truth, firefly, "autopilot", "servo")
                             + _sagging_battery(16.8, 14.0), key=lambda r: r[0]))
    plain = load_flight(path, firefly)
    stated = dataclasses.replace(firefly, motor=dataclasses.replace(firefly.motor,
                                                                    voltage=16.8))
    scaled = load_flight(path, stated)
    volts = 16.8 - 2.8 * np.clip((scaled.t - BOOT) / 4.0, 0.0, 1.0)
    np.testing.assert_allclose(scaled.rotor_speeds, plain.rotor_speeds * (volts / 16.8)[:, None],
                               rtol=2e-3)
    assert [w for w in plain.warnings if "battery fell from 16.80 to 14.0" in w]
    assert [w for w in scaled.warnings if "scaled by the battery voltage" in w]


def test_a_flight_directory_reads_its_log_with_measured_rotor_speeds(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth,
        tlog_writer: Callable[..., None]) -> None:
    """Given the flight directory, its log with ESC rpm is read over the one with servo
    outputs at the same rate, and a note says which and why; the servo log alone, named
    by meta.json, is read when the other is unreadable."""
    import json

    tlog_writer(tmp_path / "flight.tlog", _flight(truth, firefly, "autopilot", "servo"))
    tlog_writer(tmp_path / "autopilot.tlog", _flight(truth, firefly, "autopilot", "esc"))
    (tmp_path / "meta.json").write_text(json.dumps(
        {"files": {"tlog": "flight.tlog", "autopilot_log": "autopilot.tlog"}}))
    data = load_flight(tmp_path, firefly)
    assert data.source == str(tmp_path / "autopilot.tlog")
    assert [w for w in data.warnings if "estimating from autopilot.tlog: its rotor speeds "
            "(measured rpm) at 50 Hz, against flight.tlog 50 Hz" in w], data.warnings
    (tmp_path / "autopilot.tlog").write_bytes(b"\x00" * 10)
    data = load_flight(tmp_path, firefly)
    assert data.source == str(tmp_path / "flight.tlog")
    assert [w for w in data.warnings if "autopilot.tlog unreadable" in w], data.warnings
