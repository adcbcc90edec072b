"""ArduPilot DataFlash (`mavsysid.formats.dataflash`): the writer read back by pymavlink, and
reading (FMT + data messages) through load_flight."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.readers import READERS, load_flight
from mavsysid.formats.dataflash import write_dataflash
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

from mavsysid.errors import LogFormatError

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]

# Formats as ArduPilot 4.5 logs them (libraries/*/LogStructure.h).
FORMATS = {
    "VISP": (130, "QQIffffffffBB", "TimeUS,RTimeUS,CTimeMS,PX,PY,PZ,Roll,Pitch,Yaw,PErr,AErr,"
                                   "Rst,Ign"),
    "XKF1": (131, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,"
                                      "GZ,OH"),
    "XKQ": (132, "QBffff", "TimeUS,C,Q1,Q2,Q3,Q4"),
    "ESC": (133, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
    "RCOU": (134, "QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14"),
    "POS": (135, "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt"),
    "ATT": (136, "QffffffB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,AEKF"),
}
LAT0, LNG0, ALT0 = 47.397742, 8.545594, 488.0  # deg, deg, m
T0 = 30.0  # s since boot


def _euler_deg(q: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angles, deg, of NED/FRD quaternions (N, 4)."""
    w, x, y, z = q.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.degrees(np.column_stack([roll, pitch, yaw]))


def _rows(truth: Truth, vehicle: VehicleConfig, pose: str, rotors: str) -> list[Any]:
    rows: list[Any] = []
    t = T0 + np.arange(400) / 100.0
    x = truth(t)
    us = [round(v * 1e6) for v in t]
    for s, ti, p, q in zip(us, t, x["position_ned"], x["quaternion_ned"], strict=True):
        if pose == "vision":
            rows.append(("VISP", (s + 2000, 0, round(ti * 1e3), *p, *_euler_deg(q[None])[0],
                                  0.01, 0.01, 0, 0)))
        elif pose == "global":
            lat = LAT0 + np.degrees(p[0] / 6378137.0)
            lng = LNG0 + np.degrees(p[1] / (6378137.0 * np.cos(np.radians(LAT0))))
            rows.append(("POS", (s, round(lat * 1e7), round(lng * 1e7), ALT0 - p[2], 0.0, 0.0)))
            roll, pitch, yaw = _euler_deg(q[None])[0]
            rows.append(("ATT", (s, 0.0, roll, 0.0, pitch, 0.0, yaw, 1)))
        else:
            for core in (1, 0):  # the lower core is read
                shift = 0.0 if core == 0 else 1.0
                rows.append(("XKF1", (s, core, 0, 0, 0, 0.0, 0.0, 0.0, 0.0, *(p + shift),
                                      0, 0, 0, 0)))
                rows.append(("XKQ", (s, core, *q)))
    t = T0 + 0.003 + np.arange(398) / 100.0
    n = truth(t)["rotor_speeds"]
    for ti, row in zip(t, n, strict=True):
        s = round(ti * 1e6)
        if rotors == "esc":
            for i, v in enumerate(row):
                rows.append(("ESC", (s + i, i, v * 60.0 / (2.0 * np.pi), 0.0, 0.0, 0.0, 0, 0.0,
                                     0, 0.0)))
        else:
            e = vehicle.motor.thrust_expo
            f = (row / vehicle.limits.rotor_speed_max) ** 2
            u = (-(1 - e) + np.sqrt((1 - e) ** 2 + 4 * e * f)) / (2 * e)
            pwm = [round(1000 + 1000 * v) for v in u]
            rows.append(("RCOU", (s, *pwm, 1500, 0, *[0] * 6)))
    return sorted(rows, key=lambda r: r[1][0])


@pytest.mark.parametrize(
    ("pose", "rotors", "pose_source", "pose_atol", "rotor_atol"),
    [
        # VISP: ms times and float32 degrees.
        ("vision", "esc", "motion_capture", 1e-4, 0.01),
        ("ekf", "esc", "autopilot", 1e-5, 0.01),
        ("ekf", "rcou", "autopilot", 1e-5, 0.5),  # integer µs: ±0.35 rad/s
    ],
)
def test_dataflash_round_trip(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                              dataflash_writer: Callable[..., None],
                              assert_matches_truth: Callable[..., None], pose: str,
                              rotors: str, pose_source: str, pose_atol: float,
                              rotor_atol: float) -> None:
    """A NED/FRD DataFlash log reads back in ENU/FLU and rad/s, ESC instance i = rotor i + 1."""
    path = tmp_path / "00000042.BIN"
    dataflash_writer(path, FORMATS, _rows(truth, firefly, pose, rotors))
    data = load_flight(path, firefly)
    assert data.pose_source == pose_source
    assert data.rotor_count == 6
    expected_t = T0 + np.arange(400) / 100.0
    expected_t = expected_t[(expected_t >= T0 + 0.003) & (expected_t <= T0 + 3.973 + 1e-5)]
    np.testing.assert_allclose(data.t, expected_t, atol=1e-9)
    assert_matches_truth(data, truth, rotor_atol, pose_atol=pose_atol)
    assert any("RCOU" in w for w in data.warnings) == (rotors == "rcou")


def test_dataflash_global_position_fallback(tmp_path: Path, firefly: VehicleConfig,
                                            truth: Truth,
                                            dataflash_writer: Callable[..., None]) -> None:
    """POS/ATT alone give an autopilot pose, local about the first POS sample (±1e-7° ≈ 1 cm)."""
    path = tmp_path / "flight.bin"
    dataflash_writer(path, FORMATS, _rows(truth, firefly, "global", "esc"))
    data = load_flight(path, firefly)
    assert data.pose_source == "autopilot"
    x = truth(data.t)
    origin = truth(np.array([T0]))["position"]
    np.testing.assert_allclose(data.position, x["position"] - origin, atol=0.02)
    sign = np.sign(np.sum(data.quaternion * x["quaternion"], axis=1))[:, None]
    np.testing.assert_allclose(sign * data.quaternion, x["quaternion"], atol=1e-5)


REAL_LOG = (Path(__file__).resolve().parents[2] / ".." / "shared" / "real-logs"
            / "ardupilot-test.BIN")


def test_real_ardupilot_log_pose_and_inputs() -> None:
    """pymavlink's test.BIN (ArduPlane 3.8.2-dev: per-core NKF1/NKQ1, NKF4 PI = 0, RCOU C1..C14):
    the EKF2 core-0 pose with its quaternion and the RCOU outputs. It is < 1 s of an
    ArduPlane flight (RCOU drives control surfaces), so it is refused, in one line naming
    the file (for its motor outputs or its length, whichever check comes first)."""
    if not REAL_LOG.exists():
        pytest.skip(f"{REAL_LOG} absent")
    quad = load_vehicle("quad_x")
    streams = READERS[".bin"](REAL_LOG, quad)
    assert streams.pose_source == "autopilot"
    assert streams.pose is not None and streams.pose.label == "NKF1 core 0 + NKQ1 core 0"
    assert [r.label for r in streams.rotors] == ["RCOU PWM"]
    assert any("RCOU" in w for w in streams.warnings)
    with pytest.raises(LogFormatError, match=r"ardupilot-test\.BIN: ") as refused:
        load_flight(REAL_LOG, quad)
    assert "\n" not in str(refused.value)


# ------------------------------------------------ writing

_WRITTEN = {
    "MODE": (11, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "XKF1": (181, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,"
                                      "GX,GY,GZ,OH"),
    "MSG": (91, "QZ", "TimeUS,Message"),
}


def test_dataflash_round_trip_through_dfreader(tmp_path):
    from pymavlink.DFReader import DFReader_binary

    rng = np.random.default_rng(4)
    values = rng.normal(size=(5, 7))
    rows = [("MSG", (1000, b"ArduCopter V4.5.7"))]
    rows += [("XKF1", (2000 + 10 * i, 0, round(v[0] * 100), round(v[1] * 100), 1234, *v,
                       0, 0, 0, 0)) for i, v in enumerate(values)]
    rows.append(("MODE", (5000, 4, 4, 2)))
    path = tmp_path / "a.bin"
    write_dataflash(path, _WRITTEN, rows)
    log = DFReader_binary(str(path))
    got = list(iter(lambda: log.recv_match(type=["XKF1", "MODE", "MSG"]), None))
    assert [m.get_type() for m in got] == ["MSG", *["XKF1"] * 5, "MODE"]
    assert got[0].Message == "ArduCopter V4.5.7"
    xkf1 = got[1:6]
    np.testing.assert_allclose([m.TimeUS for m in xkf1], 2000 + 10 * np.arange(5))
    # Scaled characters come back in their unit (c: centi), floats at single precision.
    np.testing.assert_allclose([m.Roll for m in xkf1], np.round(values[:, 0] * 100) / 100)
    np.testing.assert_allclose([m.Yaw for m in xkf1], 12.34)
    np.testing.assert_allclose([[m.VN, m.VE, m.VD, m.dPD, m.PN, m.PE, m.PD] for m in xkf1],
                               values, rtol=1e-6)
    assert (got[6].Mode, got[6].Rsn) == (4, 2)


@pytest.mark.parametrize("formats", [
    {"MODE": (128, "QMBB", "TimeUS,Mode,ModeNum,Rsn")},
    {"MODE": (11, "QMBB", "TimeUS,Mode,ModeNum,Rsn"), "MSG": (11, "QZ", "TimeUS,Message")},
    {"MODE": (11, "QMB", "TimeUS,Mode,ModeNum,Rsn")},
    {"TOOLONG": (12, "Q", "TimeUS")},
])
def test_dataflash_bad_formats_are_refused(tmp_path, formats):
    with pytest.raises(ValueError):
        write_dataflash(tmp_path / "a.bin", formats, [])


def test_rows_by_column_name_fill_the_rest_with_zero(tmp_path):
    """A row given by column name is the row given in column order, unnamed columns 0."""
    from pymavlink.DFReader import DFReader_binary

    by_position = [("MSG", (1000, b"ArduCopter")),
                   ("XKF1", (2000, 0, 150, -250, 1234, 1.0, 2.0, 3.0, 0.0, 4.0, 5.0, 6.0,
                             0, 0, 0, 0))]
    by_name = [("MSG", {"TimeUS": 1000, "Message": b"ArduCopter"}),
               ("XKF1", {"TimeUS": 2000, "Roll": 150, "Pitch": -250, "Yaw": 1234, "VN": 1.0,
                         "VE": 2.0, "VD": 3.0, "PN": 4.0, "PE": 5.0, "PD": 6.0})]
    write_dataflash(tmp_path / "a.bin", _WRITTEN, by_position)
    write_dataflash(tmp_path / "b.bin", _WRITTEN, by_name)
    assert (tmp_path / "a.bin").read_bytes() == (tmp_path / "b.bin").read_bytes()
    xkf1 = DFReader_binary(str(tmp_path / "b.bin")).recv_match(type=["XKF1"])
    assert (xkf1.Roll, xkf1.PD, xkf1.OH) == (1.5, 6.0, 0)
    with pytest.raises(KeyError, match="Altitude"):
        write_dataflash(tmp_path / "c.bin", _WRITTEN, [("XKF1", {"TimeUS": 1, "Altitude": 2.0})])
