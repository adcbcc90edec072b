"""A synthetic flight and minimal writers of each log format, for the format and reader tests.

The flight is smooth, known in closed form, and physically consistent in its collective
thrust (Σ c_T n² = m e_z^B · (a − g)), so the hover check passes and the clock alignment
by Σ n² has something to find. The file side (NED/FRD) is derived through rotation
matrices, independently of the reader's quaternion formula.

Writers: ``.tlog`` with pymavlink's own MAVLink packer (8-byte big-endian µs receipt time,
then the packed message); ULog and DataFlash with the library's writers
(`mavsysid.formats.ulog.write_ulog`, `mavsysid.formats.dataflash.write_dataflash`). The
fixtures are registered for every test by ``tests/conftest.py``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.flight import FlightData
from mavsysid.formats.dataflash import write_dataflash
from mavsysid.formats.ulog import write_ulog
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.rotation import matrix_to_quat, quat_exp, quat_to_matrix

__all__ = ["ULOG_FORMATS", "Truth", "assert_matches_truth", "dataflash_writer",
           "synthetic_truth", "tlog_writer", "truth", "ulog_flight", "ulog_writer",
           "write_tlog"]

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]

_AMPLITUDE = np.array([0.5, 0.4, 0.2])
_OMEGA = np.array([1.3, 0.9, 1.7])
_PHASE = np.array([0.0, 0.3, 0.5])
# ENU ↔ NED (an involution) and body FLU ↔ FRD.
_T = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_B = np.diag([1.0, -1.0, -1.0])


def synthetic_truth(vehicle: VehicleConfig, t: np.ndarray) -> dict[str, np.ndarray]:
    """The synthetic flight at times t (N,): ENU/FLU and NED/FRD pose, rotor speeds."""
    t = np.asarray(t, dtype=float)
    arg = np.outer(t, _OMEGA) + _PHASE
    position = _AMPLITUDE * np.sin(arg) + np.array([0.0, 0.0, 1.0])
    acceleration = -_AMPLITUDE * _OMEGA**2 * np.sin(arg)
    rotvec = np.column_stack([0.25 * np.sin(2.1 * t), 0.2 * np.sin(1.7 * t + 0.5),
                              0.6 * np.sin(0.8 * t + 0.2)])
    quaternion = quat_exp(rotvec)
    R = quat_to_matrix(quaternion)
    specific_force = np.einsum("ni,ni->n", R[:, :, 2], acceleration + [0.0, 0.0, GRAVITY])
    k = vehicle.rotor_count
    hover = np.sqrt(vehicle.mass * specific_force / (k * vehicle.parameters.c_T))
    wiggle = 1.0 + 0.02 * np.sin(np.outer(t, np.full(k, 3.0)) + np.arange(k))
    return {
        "position": position,
        "quaternion": quaternion,
        "position_ned": position @ _T.T,
        "quaternion_ned": matrix_to_quat(_T @ R @ _B),
        "rotor_speeds": hover[:, None] * wiggle,
    }


@pytest.fixture
def truth(firefly: VehicleConfig) -> Truth:
    """The synthetic flight of the Firefly as a function of time."""
    return lambda t: synthetic_truth(firefly, t)


def _assert_matches(data: FlightData, truth: Truth, rotor_atol: float,
                    pose_atol: float = 1e-5) -> None:
    expected = truth(data.t)
    np.testing.assert_allclose(data.position, expected["position"], atol=pose_atol)
    # q and −q are one attitude.
    sign = np.sign(np.sum(data.quaternion * expected["quaternion"], axis=1))[:, None]
    np.testing.assert_allclose(sign * data.quaternion, expected["quaternion"], atol=pose_atol)
    np.testing.assert_allclose(data.rotor_speeds, expected["rotor_speeds"], atol=rotor_atol)


@pytest.fixture
def assert_matches_truth() -> Callable[..., None]:
    """Check a FlightData against the truth: (data, truth, rotor_atol, pose_atol=1e-5)."""
    return _assert_matches


# ---------------------------------------------------------------------------- tlog


def write_tlog(path: Path, records: Iterable[tuple[float, Any, tuple[int, int]]]) -> None:
    """Write (receipt time s, message, (system, component)) records as a MAVLink 2 tlog."""
    from pymavlink.dialects.v20 import ardupilotmega

    with path.open("wb") as f:
        mav = ardupilotmega.MAVLink(f, srcSystem=1, srcComponent=1)
        for receipt, message, (system, component) in sorted(records, key=lambda r: r[0]):
            mav.srcSystem, mav.srcComponent = system, component
            f.write(struct.pack(">Q", round(receipt * 1e6)))
            mav.send(message)


@pytest.fixture
def tlog_writer() -> Callable[..., None]:
    """`write_tlog`."""
    return write_tlog


# ---------------------------------------------------------------------------- ULog

ULOG_FORMATS = {
    "vehicle_mocap_odometry": "uint64_t timestamp;uint64_t timestamp_sample;float[3] position;"
                              "float[4] q;uint8_t pose_frame;",
    "vehicle_local_position": "uint64_t timestamp;uint64_t timestamp_sample;float x;float y;"
                              "float z;",
    "vehicle_attitude": "uint64_t timestamp;uint64_t timestamp_sample;float[4] q;",
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;float esc_voltage;",
    "esc_status": "uint64_t timestamp;uint8_t esc_count;esc_report[8] esc;",
    "actuator_motors": "uint64_t timestamp;uint64_t timestamp_sample;uint16_t reversible_flags;"
                       "float[12] control;",
    "actuator_outputs": "uint64_t timestamp;uint32_t noutputs;float[16] output;",
}


def ulog_flight(path: Path, truth: Truth, vehicle: VehicleConfig, pose: str | None = "mocap",
                rotors: str = "esc", t0: float = 20.0, duration: float = 4.0,
                esc_count: int | None = None,
                edit: Callable[[dict[str, list[dict[str, float]]]], None] | None = None) -> Path:
    """Write the synthetic flight as a PX4 log and return its path.

    pose: "mocap" (100 Hz odometry), "autopilot" (50 Hz local position, 100 Hz attitude
    at other instants) or None; rotors: "esc" (50 Hz rpm), "motors" (actuator_motors) or
    "outputs" (actuator_outputs PWM); edit: changes the rows before writing.
    """
    topics: dict[str, list[dict[str, float]]] = {}

    def rows(rate: float, phase: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        t = t0 + phase + np.arange(round(duration * rate)) / rate
        return t, truth(t)

    if pose == "mocap":
        t, x = rows(100.0, 0.0)
        topics["vehicle_mocap_odometry"] = [
            {"timestamp": round(ti * 1e6) + 3000, "timestamp_sample": round(ti * 1e6),
             "pose_frame": 1, **{f"position[{i}]": p[i] for i in range(3)},
             **{f"q[{i}]": q[i] for i in range(4)}}
            for ti, p, q in zip(t, x["position_ned"], x["quaternion_ned"], strict=True)]
    elif pose == "autopilot":
        t, x = rows(50.0, 0.0)
        topics["vehicle_local_position"] = [
            {"timestamp": round(ti * 1e6), "x": p[0], "y": p[1], "z": p[2]}
            for ti, p in zip(t, x["position_ned"], strict=True)]
        t, x = rows(100.0, 0.004)
        topics["vehicle_attitude"] = [
            {"timestamp": round(ti * 1e6), **{f"q[{i}]": q[i] for i in range(4)}}
            for ti, q in zip(t, x["quaternion_ned"], strict=True)]
    t, x = rows(50.0, 0.007)
    n = x["rotor_speeds"]
    k = n.shape[1]
    stamps = [round(ti * 1e6) for ti in t]
    if rotors == "esc":
        count = k if esc_count is None else esc_count
        topics["esc_status"] = [
            {"timestamp": s, "esc_count": count,
             **{f"esc[{i}].esc_rpm": round(row[i] * 60 / (2 * np.pi)) for i in range(count)}}
            for s, row in zip(stamps, n, strict=True)]
    elif rotors == "motors":
        thrust = (n / vehicle.limits.rotor_speed_max) ** 2
        topics["actuator_motors"] = [
            {"timestamp": s, **{f"control[{i}]": row[i] if i < k else np.nan
                                for i in range(12)}}
            for s, row in zip(stamps, thrust, strict=True)]
    else:
        e = vehicle.motor.thrust_expo
        s_ = (n / vehicle.limits.rotor_speed_max) ** 2
        u = (-(1 - e) + np.sqrt((1 - e) ** 2 + 4 * e * s_)) / (2 * e)
        topics["actuator_outputs"] = [
            {"timestamp": s, "noutputs": 8, **{f"output[{i}]": row[i] for i in range(k)}}
            for s, row in zip(stamps, 1000.0 + 1000.0 * u, strict=True)]
    if edit is not None:
        edit(topics)
    write_ulog(path, ULOG_FORMATS, topics)
    return path


@pytest.fixture
def ulog_writer() -> Callable[..., Path]:
    """`ulog_flight`: (path, truth, vehicle, pose=…, rotors=…, …) → path."""
    return ulog_flight


# ---------------------------------------------------------------------------- DataFlash


@pytest.fixture
def dataflash_writer() -> Callable[..., None]:
    """`write_dataflash`."""
    return write_dataflash
