"""Autopilot logs in the project's conventions: motor outputs refused or in the config's order."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.vehicle.config import RotorConfig, VehicleConfig, load_vehicle, save_vehicle

from mavsysid.errors import LogFormatError
from tests.support.synthetic_logs import synthetic_truth

# Config rotor (0-based) of motor output 1..4 for quad_x's rotor list (front left, rear
# left, rear right, front right): ArduPilot's and PX4's quad X motors are front right,
# rear left, front left, rear right.
QUAD_X_OUTPUTS = (3, 1, 0, 2)
T0 = 30.0


@pytest.fixture
def ardupilot_quad(tmp_path: Path) -> VehicleConfig:
    """quad_x with ArduPilot's quad-X spin directions, naming its frame."""
    quad = load_vehicle("quad_x")
    rotors = tuple(RotorConfig(r.position, -r.direction) for r in quad.rotors)
    path = tmp_path / "ardupilot_quad.toml"
    save_vehicle(replace(quad, rotors=rotors, autopilot_frame="ardupilot:quad_x"), path)
    return load_vehicle(path)


def _dataflash_rows(truth: Callable[[np.ndarray], dict[str, np.ndarray]],
                    order: tuple[int, ...]) -> list[tuple[str, tuple[float, ...]]]:
    """EKF3 pose and ESC rpm by instance, ESC i carrying config rotor order[i]."""
    rows: list[tuple[str, tuple[float, ...]]] = []
    t = T0 + np.arange(400) / 100.0
    x = truth(t)
    for ti, p, q in zip(t, x["position_ned"], x["quaternion_ned"], strict=True):
        s = round(ti * 1e6)
        rows.append(("XKF1", (s, 0, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, *p, 0, 0, 0, 0)))
        rows.append(("XKQ", (s, 0, *q)))
    t = T0 + 0.003 + np.arange(398) / 100.0
    n = truth(t)["rotor_speeds"][:, list(order)]
    for ti, row in zip(t, n, strict=True):
        for i, v in enumerate(row):
            rows.append(("ESC", (round(ti * 1e6) + i, i, v * 60.0 / (2.0 * np.pi), 0.0, 0.0,
                                 0.0, 0, 0.0, 0, 0.0)))
    return sorted(rows, key=lambda r: r[1][0])


FORMATS = {
    "XKF1": (131, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,"
                                      "GZ,OH"),
    "XKQ": (132, "QBffff", "TimeUS,C,Q1,Q2,Q3,Q4"),
    "ESC": (133, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
}


def test_dataflash_in_ardupilot_order_reads_in_config_order(
        tmp_path: Path, ardupilot_quad: VehicleConfig,
        dataflash_writer: Callable[..., None]) -> None:
    """ESC instance i is ArduPilot's motor i + 1; FlightData columns are the config's rotors."""
    def truth(t: np.ndarray) -> dict[str, np.ndarray]:
        return synthetic_truth(ardupilot_quad, t)

    path = tmp_path / "00000001.BIN"
    dataflash_writer(path, FORMATS, _dataflash_rows(truth, QUAD_X_OUTPUTS))
    data = load_flight(path, ardupilot_quad)
    expected = truth(data.t)["rotor_speeds"]
    np.testing.assert_allclose(data.rotor_speeds, expected, atol=0.01)
    # Without the frame the same log is read one to one, so the columns are not the rotors.
    plain = load_flight(path, replace(ardupilot_quad, autopilot_frame=None))
    assert not np.allclose(plain.rotor_speeds, expected, atol=0.5)


def test_ulog_in_px4_order_reads_in_config_order(
        tmp_path: Path, ardupilot_quad: VehicleConfig,
        ulog_writer: Callable[..., Path]) -> None:
    vehicle = replace(ardupilot_quad, autopilot_frame="px4:quad_x")

    def in_output_order(t: np.ndarray) -> dict[str, np.ndarray]:
        x = synthetic_truth(vehicle, t)
        return {**x, "rotor_speeds": x["rotor_speeds"][:, list(QUAD_X_OUTPUTS)]}

    path = ulog_writer(tmp_path / "flight.ulg", in_output_order, vehicle)
    data = load_flight(path, vehicle)
    # esc_rpm is logged as whole rpm: ±0.05 rad/s.
    np.testing.assert_allclose(data.rotor_speeds,
                               synthetic_truth(vehicle, data.t)["rotor_speeds"], atol=0.06)


def _eight_outputs(topics: dict[str, list[dict[str, float]]]) -> None:
    """Outputs 5-8 of a VTOL or an octocopter: moving like motors."""
    for j, row in enumerate(topics["actuator_outputs"]):
        row.update({f"output[{i}]": 1200.0 + 10.0 * ((i + j) % 7) for i in range(4, 8)})


def test_more_motor_outputs_than_rotors_is_refused(
        tmp_path: Path, ulog_writer: Callable[..., Path]) -> None:
    quad = load_vehicle("quad_x")
    path = ulog_writer(tmp_path / "vtol.ulg", lambda t: synthetic_truth(quad, t), quad,
                       rotors="outputs", edit=_eight_outputs)
    with pytest.raises(LogFormatError) as info:
        load_flight(path, quad)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: the log has 8 motor outputs (actuator_outputs PWM), "
                              "vehicle quad_x has 4 rotors; name the autopilot frame in the "
                              'vehicle file ([autopilot] frame = "ardupilot:quad_plus"')
    assert message.endswith("or use a vehicle with 8 rotors")


def test_named_frame_takes_its_motors_of_more_outputs(
        tmp_path: Path, ardupilot_quad: VehicleConfig,
        ulog_writer: Callable[..., Path]) -> None:
    """With the frame named, outputs 1-4 are its motors; the rest are left out, with a note."""
    def in_output_order(t: np.ndarray) -> dict[str, np.ndarray]:
        x = synthetic_truth(ardupilot_quad, t)
        return {**x, "rotor_speeds": x["rotor_speeds"][:, list(QUAD_X_OUTPUTS)]}

    path = ulog_writer(tmp_path / "vtol.ulg", in_output_order, ardupilot_quad,
                       rotors="outputs", edit=_eight_outputs)
    data = load_flight(path, ardupilot_quad)
    assert data.rotor_count == 4
    expected = synthetic_truth(ardupilot_quad, data.t)["rotor_speeds"]
    # PWM through the motor curve: float32 samples, so a loose tolerance.
    np.testing.assert_allclose(data.rotor_speeds, expected, atol=0.5)
    assert any("motor outputs 5..8 are not motors of ardupilot:quad_x" in w
               for w in data.warnings)


def _normalised_outputs(topics: dict[str, list[dict[str, float]]]) -> None:
    """actuator_outputs as a mixer's 0..1 where PWM (1000–2000 µs) was."""
    for row in topics["actuator_outputs"]:
        row.update({key: (value - 1000.0) / 1000.0 for key, value in row.items()
                    if key.startswith("output[") and value > 1000.0})


def test_motor_outputs_that_are_not_pwm_give_no_rotor_speeds(
        tmp_path: Path, ulog_writer: Callable[..., Path]) -> None:
    """Outputs in another unit are refused in one line, not clipped into a made-up c_T."""
    quad = load_vehicle("quad_x")
    path = ulog_writer(tmp_path / "mixer.ulg", lambda t: synthetic_truth(quad, t), quad,
                       rotors="outputs", edit=_normalised_outputs)
    with pytest.raises(LogFormatError) as info:
        load_flight(path, quad)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: actuator_outputs: the motor outputs are not PWM in the "
                              "vehicle's [motor] range")
