"""DataFlash logs of each ArduPilot generation: every motor input and pose source reads back.

The message definitions (FMT name, format, columns) are ArduPilot's own, from its log
structure sources of each era (``libraries/DataFlash/DataFlash.h`` of ArduCopter 3.2,
``libraries/DataFlash/LogStructure.h`` of 3.3–3.6, ``libraries/AP_Logger``,
``AP_NavEKF3``/``AP_ESC_Telem`` ``LogStructure.h`` of 4.x). The writer packs raw struct
values, so scaled formats get raw integers here (``c`` centi-units, ``L`` 1e-7 deg), as
the autopilot writes them.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.vehicle.config import VehicleConfig

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]
Row = tuple[str, tuple[Any, ...]]

_EKF1_36 = ("QccCfffffffccce", "TimeUS,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH")
_EKF1_4X = ("QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH")
_EKF4_36 = ("QcccccfbbHBHHb", "TimeUS,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI")
_EKF4_4X = ("QBcccccfffHBIHb", "TimeUS,C,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI")
_QUAT_36 = ("Qffff", "TimeUS,Q1,Q2,Q3,Q4")
_QUAT_4X = ("QBffff", "TimeUS,C,Q1,Q2,Q3,Q4")

# name: (format, columns); type ids are given in order when writing.
DEFINITIONS: dict[str, tuple[str, str]] = {
    # ArduCopter 3.2 (DataFlash.h LOG_COMMON_STRUCTURES, ArduCopter LogStructure).
    "RCOU_Chan": ("Ihhhhhhhh", "TimeMS,Chan1,Chan2,Chan3,Chan4,Chan5,Chan6,Chan7,Chan8"),
    "EKF1_32": ("IccCffffffccc", "TimeMS,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD,GX,GY,GZ"),
    "ATT_32": ("IccccCC", "TimeMS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw"),
    # The TimeMS generation after it: RCOU Ch1..Ch12, ESC1..ESC8 "Icccc".
    "RCOU_Ch": ("Ihhhhhhhhhhhh", "TimeMS,Ch1,Ch2,Ch3,Ch4,Ch5,Ch6,Ch7,Ch8,Ch9,Ch10,Ch11,Ch12"),
    "ESCn_Icccc": ("Icccc", "TimeMS,RPM,Volt,Curr,Temp"),
    # ArduCopter 3.3–3.4: ESC1..ESC8 "Qcccc" (rpm logged as int16 rpm/10).
    "ESCn_Qcccc": ("Qcccc", "TimeUS,RPM,Volt,Curr,Temp"),
    # ArduCopter 3.5–3.6: per-core EKF names, ATT in centi-degrees, ESCn "QeCCcH".
    "ESCn_QeCCcH": ("QeCCcH", "TimeUS,RPM,Volt,Curr,Temp,CTot"),
    "ATT_36": ("QccccCCCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw"),
    "RCOU_C": ("QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14"),
    **{f"{k}_36": _EKF1_36 for k in ("NKF1", "NKF6", "XKF1", "XKF6")},
    **{f"{k}_36": _EKF4_36 for k in ("NKF4", "XKF4")},
    **{f"{k}_36": _QUAT_36 for k in ("NKQ1", "NKQ2", "XKQ1", "XKQ2")},
    # ArduPilot 4.x: core index C in each row, ESC with Instance.
    **{f"{k}_4x": _EKF1_4X for k in ("NKF1", "XKF1")},
    **{f"{k}_4x": _EKF4_4X for k in ("NKF4", "XKF4")},
    **{f"{k}_4x": _QUAT_4X for k in ("NKQ", "XKQ")},
    "ESC_e": ("QBeffcfcff", "TimeUS,Instance,RPM,Volt,Curr,Temp,CTot,MotTemp,Err,RXErr"),
    "ESC_f": ("QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
}
T0 = 30.0  # s since boot
WRONG = 0  # the EKF core that is not primary: PI flags core 1, not the lowest


def _stamp(key: str, t: float) -> int:
    ms = DEFINITIONS[key][1].startswith("TimeMS")
    return round(t * 1e3) if ms else round(t * 1e6)


def _centi_euler(q: np.ndarray) -> tuple[int, int, int]:
    """Z-Y-X Euler angles of a NED/FRD quaternion as ATT writes them: centi-degrees."""
    w, x, y, z = q
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return (round(np.degrees(roll) * 100), round(np.degrees(pitch) * 100),
            round(np.degrees(yaw) % 360.0 * 100))


def _ekf_rows(kind: str, t: float, p: np.ndarray, q: np.ndarray) -> list[Row]:
    """EKF rows of both cores; core WRONG is off by 1 m and a different attitude."""
    family, layout = kind.split("_")  # "XKF_4x", "NKF_36"
    quat = "XKQ" if family == "XKF" else "NKQ"
    rows: list[Row] = []
    for core in (0, 1):
        pc = p + (1.0 if core == WRONG else 0.0)
        qc = q[[1, 0, 3, 2]] if core == WRONG else q
        if layout == "4x":
            rows.append((f"{family}1_4x", (_stamp(f"{family}1_4x", t), core, 0, 0, 0, 0.0,
                                           0.0, 0.0, 0.0, *pc, 0, 0, 0, 0)))
            rows.append((f"{quat}_4x", (_stamp(f"{quat}_4x", t), core, *qc)))
            rows.append((f"{family}4_4x", (_stamp(f"{family}4_4x", t), core, *[0] * 5,
                                           0.0, 0.0, 0.0, 0, 0, 0, 0, 1 - WRONG)))
        else:
            name = f"{family}{1 + 5 * core}_36"
            rows.append((name, (_stamp(name, t), 0, 0, 0, 0.0, 0.0, 0.0, 0.0, *pc, 0, 0, 0,
                                0)))
            rows.append((f"{quat}{1 + core}_36", (_stamp(f"{quat}{1 + core}_36", t), *qc)))
            if core == 0:
                rows.append((f"{family}4_36", (_stamp(f"{family}4_36", t), *[0] * 5, 0.0,
                                               0, 0, 0, 0, 0, 0, 1 - WRONG)))
    return rows


def _pose_rows(kind: str, t: float, p: np.ndarray, q: np.ndarray) -> list[Row]:
    if kind == "NKF1_36+ATT_36":
        att = ("ATT_36", (_stamp("ATT_36", t), 0, _centi_euler(q)[0], 0, _centi_euler(q)[1],
                          0, _centi_euler(q)[2], 0, 0))
        return [("NKF1_36", (_stamp("NKF1_36", t), 0, 0, 0, 0.0, 0.0, 0.0, 0.0, *p, 0, 0, 0,
                             0)), att]
    if kind == "EKF1_32+ATT_32":
        roll, pitch, yaw = _centi_euler(q)
        return [("EKF1_32", (_stamp("EKF1_32", t), 0, 0, 0, 0.0, 0.0, 0.0, *p, 0, 0, 0)),
                ("ATT_32", (_stamp("ATT_32", t), 0, roll, 0, pitch, 0, yaw))]
    return _ekf_rows(kind, t, p, q)


def _rotor_rows(kind: str, t: float, n: np.ndarray, vehicle: VehicleConfig) -> list[Row]:
    rpm = n * 60.0 / (2.0 * np.pi)
    if kind.startswith("RCOU"):
        e = vehicle.motor.thrust_expo
        f = (n / vehicle.limits.rotor_speed_max) ** 2
        u = (-(1 - e) + np.sqrt((1 - e) ** 2 + 4 * e * f)) / (2 * e)
        pwm = [round(1000 + 1000 * v) for v in u]
        channels = len(DEFINITIONS[kind][1].split(",")) - 1
        return [(kind, (_stamp(kind, t), *pwm, 1500, *[0] * (channels - len(pwm) - 1)))]
    if kind.startswith("ESCn"):
        # "c": int16 rpm/10 as ArduPilot 3.3–3.4 wrote it; "e": int32 rpm·100.
        raw = [round(r / 10) if "cccc" in kind else round(r * 100) for r in rpm]
        tail = (0, 0, 0) if "cccc" in kind else (0, 0, 0, 0)
        return [(f"{kind}#{i + 1}", (_stamp(kind, t), v, *tail))
                for i, v in enumerate(raw)]
    raw = [round(r * 100) for r in rpm] if kind == "ESC_e" else list(rpm)
    rest = (0.0, 0.0, 0, 0.0, 0, 0.0, 0.0) if kind == "ESC_e" else (0.0, 0.0, 0.0, 0, 0.0,
                                                                    0, 0.0)
    return [(kind, (_stamp(kind, t) + i, i, v, *rest)) for i, v in enumerate(raw)]


def _write(path: Path, writer: Callable[..., None], rows: list[Row]) -> None:
    """Name each used definition as the log does (ESC1.., RCOU, XKF1…) and write."""
    def log_name(key: str) -> str:
        base, _, index = key.partition("#")
        name = base.split("_")[0]
        return f"ESC{index}" if name == "ESCn" else name

    keys = list(dict.fromkeys(key for key, _ in rows))
    formats = {log_name(k): (100 + i, *DEFINITIONS[k.partition("#")[0]])
               for i, k in enumerate(keys)}
    writer(path, formats, [(log_name(k), v) for k, v in rows])


def _flight(truth: Truth, vehicle: VehicleConfig, pose: str, rotors: str) -> list[Row]:
    rows: list[Row] = []
    t = T0 + np.arange(400) / 100.0
    x = truth(t)
    for ti, p, q in zip(t, x["position_ned"], x["quaternion_ned"], strict=True):
        rows += _pose_rows(pose, ti, p, q)
    t = T0 + 0.003 + np.arange(398) / 100.0
    for ti, n in zip(t, truth(t)["rotor_speeds"], strict=True):
        rows += _rotor_rows(rotors, ti, n, vehicle)
    return sorted(rows, key=lambda r: r[1][0] * (1000 if "MS" in DEFINITIONS[
        r[0].partition("#")[0]][1][:6] else 1))


@pytest.mark.parametrize(
    ("pose", "rotors", "rotor_atol", "pose_atol"),
    [
        # ArduCopter 3.2: TimeMS, RCOU Chan1..Chan8, EKF1 + centi-degree ATT.
        ("EKF1_32+ATT_32", "RCOU_Chan", 0.5, 1e-4),
        # RCOU Ch1..Ch12 (TimeMS); int16 rpm/10 ESCs: 10 rpm steps (±0.53 rad/s).
        ("EKF1_32+ATT_32", "RCOU_Ch", 0.5, 1e-4),
        ("EKF1_32+ATT_32", "ESCn_Icccc", 0.6, 1e-4),
        ("NKF1_36+ATT_36", "ESCn_Qcccc", 0.6, 1e-4),
        # 3.5–3.6: per-core names, core 1 flagged primary by NKF4/XKF4 PI.
        ("NKF_36", "ESCn_QeCCcH", 0.01, 1e-5),
        ("XKF_36", "RCOU_C", 0.5, 1e-5),
        # 4.x: core index C in each row.
        ("NKF_4x", "ESC_e", 0.01, 1e-5),
        ("XKF_4x", "ESC_f", 0.01, 1e-5),
    ],
)
def test_dataflash_generation_round_trip(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                                         dataflash_writer: Callable[..., None],
                                         assert_matches_truth: Callable[..., None], pose: str,
                                         rotors: str, rotor_atol: float,
                                         pose_atol: float) -> None:
    """Each generation's fields read back as the truth, from the primary EKF core."""
    path = tmp_path / "00000007.BIN"
    _write(path, dataflash_writer, _flight(truth, firefly, pose, rotors))
    data = load_flight(path, firefly)
    assert data.pose_source == "autopilot"
    assert data.rotor_count == 6
    assert data.t.shape[0] > 390
    assert_matches_truth(data, truth, rotor_atol, pose_atol=pose_atol)
    assert any("RCOU" in w for w in data.warnings) == rotors.startswith("RCOU")
