"""PX4 ULog (`mavsysid.formats.ulog`): the writer read back by pyulog; reading, through load_flight.

Flights are written with the synthetic-flight writer (`tests.support.synthetic_logs`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.readers import READERS, load_flight
from mavsysid.formats.ulog import flattened_fields, write_ulog
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

from mavsysid.errors import LogFormatError
from tests.support.synthetic_logs import ULOG_FORMATS

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]


@pytest.mark.parametrize(
    ("pose", "rotors", "pose_source", "rotor_atol"),
    [
        ("mocap", "esc", "motion_capture", 0.1),  # integer rpm: ±0.05 rad/s
        ("autopilot", "esc", "autopilot", 0.1),
        ("mocap", "motors", "motion_capture", 0.02),
        ("mocap", "outputs", "motion_capture", 0.02),
    ],
)
def test_ulog_round_trip(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                         ulog_writer: Callable[..., Path],
                         assert_matches_truth: Callable[..., None], pose: str, rotors: str,
                         pose_source: str, rotor_atol: float) -> None:
    """A NED/FRD ULog flight reads back in ENU/FLU, rad/s, on the pose times in the rotor span."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, pose=pose, rotors=rotors)
    data = load_flight(path, firefly)
    assert data.pose_source == pose_source
    assert data.source == str(path)
    rate = 100.0 if pose == "mocap" else 50.0
    expected_t = 20.0 + np.arange(400 if pose == "mocap" else 200) / rate
    # Rotor speeds cover [20.007, 23.987] s: pose samples outside are dropped.
    expected_t = expected_t[(expected_t >= 20.007) & (expected_t <= 23.987)]
    np.testing.assert_allclose(data.t, expected_t, atol=1e-9)
    assert_matches_truth(data, truth, rotor_atol)
    curve_notes = [w for w in data.warnings if "commanded, not measured" in w]
    assert len(curve_notes) == (rotors != "esc")
    assert len(data.warnings) == len(curve_notes)


def test_ulog_unused_motor_columns_are_dropped(tmp_path: Path, firefly: VehicleConfig,
                                               truth: Truth,
                                               ulog_writer: Callable[..., Path]) -> None:
    """actuator_motors columns that are NaN throughout are not rotors; NaN elsewhere is 0."""

    def stop_first_motor(topics: dict[str, list[dict[str, float]]]) -> None:
        for row in topics["actuator_motors"][:5]:
            row["control[0]"] = np.nan

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, rotors="motors",
                       edit=stop_first_motor)
    data = load_flight(path, firefly)
    assert data.rotor_count == 6
    assert data.rotor_speeds[0, 0] == 0.0


# ------------------------------------------------ which rotor input, which instance

REAL_LOGS = Path(__file__).resolve().parents[2] / ".." / "shared" / "real-logs"

Topics = dict[Any, list[dict[str, float]]]


def _rows_at(rows: list[dict[str, float]], rate: float) -> list[dict[str, float]]:
    """Every row of a 50 Hz topic that falls on a `rate` Hz grid (rate divides 50)."""
    return rows[::round(50.0 / rate)]


def _esc_rows(topics: Topics, firefly: VehicleConfig, truth: Truth,
              rate: float) -> list[dict[str, float]]:
    """esc_status rows at `rate` Hz from the truth, for a log that has motor commands."""
    stamps = np.array([row["timestamp"] for row in topics["actuator_motors"]])[::round(50 / rate)]
    n = truth(stamps * 1e-6)["rotor_speeds"]
    return [{"timestamp": int(s), "esc_count": n.shape[1],
             **{f"esc[{i}].esc_rpm": round(v * 60 / (2 * np.pi)) for i, v in enumerate(row)}}
            for s, row in zip(stamps, n, strict=True)]


@pytest.mark.parametrize(("esc_rate", "expected"), [(4.0, "actuator_motors"),
                                                    (50.0, "esc_status rpm")])
def test_slow_esc_status_gives_way_to_faster_motor_commands(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth, esc_rate: float, expected: str,
        ulog_writer: Callable[..., Path]) -> None:
    """Measured rpm at 50 Hz is used; at 4 Hz the 50 Hz commands are, and a note says why."""

    def add_esc(topics: Topics) -> None:
        topics["esc_status"] = _esc_rows(topics, firefly, truth, esc_rate)

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, rotors="motors", edit=add_esc)
    data = load_flight(path, firefly)
    why = [w for w in data.warnings if "esc_status rpm sampled only every 0.24" in w]
    assert len(why) == (expected == "actuator_motors"), data.warnings
    if why:
        assert "actuator_motors every 0.02 s" in why[0] and "commanded" in why[0]
    np.testing.assert_allclose(data.rotor_speeds, truth(data.t)["rotor_speeds"],
                               atol=0.02 if expected == "actuator_motors" else 0.1)


def test_slow_esc_status_alone_is_used_not_refused(tmp_path: Path, firefly: VehicleConfig,
                                                   truth: Truth,
                                                   ulog_writer: Callable[..., Path]) -> None:
    """4 Hz rpm with nothing faster: read, said, and carried with its samples for the filter."""

    def slow(topics: Topics) -> None:
        topics["esc_status"] = _rows_at(topics["esc_status"], 4.0 + 1.0 / 6.0)

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, duration=8.0, edit=slow)
    data = load_flight(path, firefly)
    assert [w for w in data.warnings if "esc_status rpm sampled only every 0.24 s" in w]
    assert data.inputs is not None
    (t_esc, _), = data.inputs.series
    assert np.median(np.diff(t_esc)) == pytest.approx(0.24)
    error = np.abs(data.rotor_speeds - truth(data.t)["rotor_speeds"])
    assert np.all(np.isfinite(data.rotor_speeds)) and error.max() < 0.05 * 500


def test_esc_actuator_function_picks_and_orders_the_motor_escs(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth,
        ulog_writer: Callable[..., Path]) -> None:
    """ESCs are matched to motors by actuator_function (101 = Motor1); others are dropped."""
    k = firefly.rotor_count
    order = [5, 3, 1, 0, 2, 4]  # ESC i drives motor order[i] + 1; ESCs 6, 7 drive no motor
    captured: Topics = {}

    def shuffle(topics: Topics) -> None:
        for row in topics["esc_status"]:
            rpm = [row[f"esc[{i}].esc_rpm"] for i in range(k)]
            row["esc_count"] = 8
            for i, motor in enumerate(order):
                row[f"esc[{i}].esc_rpm"] = rpm[motor]
                row[f"esc[{i}].actuator_function"] = 101 + motor
            row.update({"esc[6].esc_rpm": 9999, "esc[6].actuator_function": 45,
                        "esc[7].esc_rpm": 9999, "esc[7].actuator_function": 0})
        captured.update(topics)

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, edit=shuffle)
    formats = {**ULOG_FORMATS,
               "esc_report": ULOG_FORMATS["esc_report"] + "uint8_t actuator_function;"}
    write_ulog(path, formats, captured)
    data = load_flight(path, firefly)
    np.testing.assert_allclose(data.rotor_speeds, truth(data.t)["rotor_speeds"], atol=0.1)


def test_multi_instance_topics_use_the_motors_and_the_primary_pose(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth,
        ulog_writer: Callable[..., Path]) -> None:
    """actuator_outputs on instance 1 (instance 0 holds still servos); a second
    vehicle_local_position instance (another estimator, 100 m off) is not mixed in."""

    def instances(topics: Topics) -> None:
        motors = topics.pop("actuator_outputs")
        topics[("actuator_outputs", 1)] = motors
        topics["actuator_outputs"] = [{"timestamp": row["timestamp"], "noutputs": 8,
                                       **{f"output[{i}]": 1500.0 for i in range(8)}}
                                      for row in motors]
        topics[("vehicle_local_position", 1)] = [
            {**row, "x": row["x"] + 100.0} for row in topics["vehicle_local_position"]]

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, pose="autopilot",
                       rotors="outputs", edit=instances)
    data = load_flight(path, firefly)
    expected = truth(data.t)
    np.testing.assert_allclose(data.position, expected["position"], atol=1e-5)
    np.testing.assert_allclose(data.rotor_speeds, expected["rotor_speeds"], atol=0.02)


def test_commanded_rotor_speeds_follow_the_battery_status_voltage(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth,
        ulog_writer: Callable[..., Path]) -> None:
    """actuator_outputs with battery_status falling 16.8 → 14.0 V: with [motor] voltage
    16.8 the rotor speeds are the curve's times V/16.8; without it the curve's, and a note
    says how far the battery fell."""
    captured: Topics = {}

    def sagging(topics: Topics) -> None:
        topics["battery_status"] = [
            {"timestamp": round(ti * 1e6),
             "voltage_v": 16.8 - 2.8 * float(np.clip((ti - 20.0) / 4.0, 0.0, 1.0))}
            for ti in np.arange(19.0, 25.0, 0.1)]
        captured.update(topics)

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, rotors="outputs",
                       duration=4.0, edit=_without("battery_status", sagging))
    write_ulog(path, {**ULOG_FORMATS, "battery_status": "uint64_t timestamp;float voltage_v;"},
               captured)
    plain = load_flight(path, firefly)
    stated = dataclasses.replace(firefly, motor=dataclasses.replace(firefly.motor,
                                                                    voltage=16.8))
    scaled = load_flight(path, stated)
    volts = 16.8 - 2.8 * np.clip((scaled.t - 20.0) / 4.0, 0.0, 1.0)
    np.testing.assert_allclose(scaled.rotor_speeds, plain.rotor_speeds * (volts / 16.8)[:, None],
                               rtol=2e-3)
    assert [w for w in plain.warnings if "battery fell from 16.80 to 14." in w]
    assert [w for w in scaled.warnings if "scaled by the battery voltage" in w]


def _without(name: str, edit: Callable[[Topics], None]) -> Callable[[Topics], None]:
    """``edit``, then ``name`` taken out again (the writer's formats do not have it)."""

    def run(topics: Topics) -> None:
        edit(topics)
        topics.pop(name)

    return run


def test_real_px4_log_with_4_hz_esc_status_reads_its_motor_commands() -> None:
    """pyulog's sample_px4_events.ulg: esc_status at ~4 Hz, actuator_motors at 10 Hz. Through
    quad_x's curve the commands contradict the log's own ESC rpm: refused in one line; with
    rotor_speed_max corrected as the message says, they read and agree."""
    path = REAL_LOGS / "px4-sample_px4_events.ulg"
    if not path.is_file():
        pytest.skip(f"no {path}")
    with pytest.raises(LogFormatError, match="what the log's own ESC rpm says") as refused:
        load_flight(path, load_vehicle("quad_x"))
    assert "\n" not in str(refused.value)
    factor = float(re.search(r"rotor_speed_max × ([\d.]+)", str(refused.value)).group(1))
    quad = load_vehicle("quad_x")
    quad = dataclasses.replace(quad, limits=dataclasses.replace(
        quad.limits, rotor_speed_max=quad.limits.rotor_speed_max * factor))
    streams = READERS[".ulg"](path, quad)
    (rotors,) = streams.rotors
    assert rotors.label == "actuator_motors" and rotors.values.shape[1] == 4
    assert [w for w in streams.warnings if "esc_status rpm sampled only every 0.248 s" in w]
    assert rotors.values.max() > 0.5 * quad.limits.rotor_speed_max * np.sqrt(0.5)
    # Within the tolerance, the curve takes the ESC's scale, and c_T its σ.
    fitted = [w for w in streams.warnings if "the motor curve's scale fitted" in w]
    assert len(fitted) == 1, streams.warnings
    assert 0.0 < streams.rotor_scale_sigma < 0.05
    off = dataclasses.replace(quad, limits=dataclasses.replace(
        quad.limits, rotor_speed_max=quad.limits.rotor_speed_max * 0.9))
    (rescaled,) = READERS[".ulg"](path, off).rotors
    np.testing.assert_allclose(rescaled.values, rotors.values, rtol=1e-9)


# ------------------------------------------------ writing

_ULOG_FORMATS = {
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;float esc_voltage;",
    "esc_status": "uint64_t timestamp;uint8_t esc_count;esc_report[2] esc;",
    "vehicle_attitude": "uint64_t timestamp;float[4] q;",
}


def test_flattened_fields_expand_arrays_and_nested_types():
    fields = flattened_fields("esc_status", _ULOG_FORMATS)
    assert [name for name, _ in fields] == [
        "timestamp", "esc_count", "esc[0].timestamp", "esc[0].esc_rpm", "esc[0].esc_voltage",
        "esc[1].timestamp", "esc[1].esc_rpm", "esc[1].esc_voltage"]
    assert "".join(code for _, code in fields) == "QBQifQif"


def test_ulog_round_trip_through_pyulog(tmp_path):
    from pyulog import ULog

    rng = np.random.default_rng(5)
    q = rng.normal(size=(6, 4))
    rpm = rng.integers(1000, 20000, size=(4, 2))
    topics = {
        "vehicle_attitude": [{"timestamp": 1000 * (i + 1), **{f"q[{c}]": q[i, c]
                                                              for c in range(4)}}
                             for i in range(6)],
        "esc_status": [{"timestamp": 1500 * (i + 1), "esc_count": 2,
                        **{f"esc[{m}].esc_rpm": int(rpm[i, m]) for m in range(2)}}
                       for i in range(4)],
        ("vehicle_attitude", 1): [{"timestamp": 7, "q[0]": 1.0}],
    }
    path = tmp_path / "a.ulg"
    write_ulog(path, _ULOG_FORMATS, topics, info={"sys_name": "PX4"}, start_us=500)
    ulog = ULog(str(path))
    assert ulog.msg_info_dict["sys_name"] == "PX4"
    assert ulog.start_timestamp == 500
    data = {(d.name, d.multi_id): d.data for d in ulog.data_list}
    np.testing.assert_allclose(np.column_stack([data["vehicle_attitude", 0][f"q[{c}]"]
                                                for c in range(4)]), q, rtol=1e-6)
    np.testing.assert_array_equal(data["vehicle_attitude", 1]["timestamp"], [7])
    esc = data["esc_status", 0]
    np.testing.assert_array_equal(np.column_stack([esc["esc[0].esc_rpm"],
                                                   esc["esc[1].esc_rpm"]]), rpm)
    np.testing.assert_array_equal(esc["esc[1].esc_voltage"], 0.0)  # missing fields are 0
