"""Fuzzed IMU messages of every autopilot log format: read, or refused in one line.

A clean short log of each format (DataFlash IMU/GYR/ACC/ISBH/ISBD/RATE with RCOU and ESC,
ULog sensor_combined/vehicle_angular_velocity with actuator_outputs and esc_status, tlog
HIGHRES_IMU/SCALED_IMU/RAW_IMU/ATTITUDE with SERVO_OUTPUT_RAW) gets its IMU fields
replaced by extreme values (NaN, ±inf, 1e30, 0, the integer type's limits: a batch
multiplier of 0, a sample rate of 0, a batch sequence number far beyond the batch, an
instance of 255, a timestamp of 0 or 2⁶³) and its bytes mutated
(`tests.support.log_fuzz.BYTE_MUTATIONS`). The reader must return a `ParsedLog` whose IMU
series are well-formed (N samples of 3 axes at N times) or raise `LogFormatError` /
`InputError` in one line naming the file, and print nothing.
"""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.formats.dataflash import ISB_ACCEL, ISB_GYRO, read_dataflash, write_dataflash
from mavsysid.formats.parsed_log import ParsedLog
from mavsysid.formats.tlog import read_tlog
from mavsysid.formats.ulog import read_ulog, write_ulog
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError, LogFormatError
from tests.formats.test_imu_readers import DATAFLASH_FORMATS, ULOG_FORMATS
from tests.support.log_fuzz import BYTE_MUTATIONS

_T0 = 30.0
_FLOATS = [np.nan, np.inf, -np.inf, 1e30, -1e30, 0.0, 1e-40]


def _extreme(rng: np.random.Generator, kind: str) -> Any:
    """An extreme value for a field of struct code ``kind``."""
    if kind in "fd":
        return float(rng.choice(_FLOATS))
    bits = {"b": 8, "B": 8, "h": 16, "H": 16, "i": 32, "I": 32, "q": 64, "Q": 64}[kind]
    signed = kind.islower()
    top = (1 << (bits - 1)) - 1 if signed else (1 << bits) - 1
    choices = [0, top, -top - 1 if signed else 1, 7]
    return choices[int(rng.integers(0, len(choices)))]  # exact: no float on the way


# --- DataFlash -------------------------------------------------------------------------------

_DF_CODES = {"f": "f", "Q": "Q", "B": "B", "H": "H", "I": "I", "h": "h"}


def _dataflash_rows(rng: np.random.Generator) -> list[tuple[str, dict[str, Any]]]:
    """A clean IMU/GYR/ACC/ISB/RATE log with motor outputs, IMU fields then fuzzed."""
    t = _T0 + np.arange(120) / 200.0
    rows: list[tuple[str, dict[str, Any]]] = []
    for j, ti in enumerate(t):
        us = round(ti * 1e6)
        values = {"GyrX": 0.1, "GyrY": -0.2, "GyrZ": 0.05, "AccX": 0.3, "AccY": -0.1,
                  "AccZ": -9.8}
        rows.append(("IMU", {"TimeUS": us, "I": j % 2, **values}))
        rows.append(("GYR", {"TimeUS": us, "I": 0, "SampleUS": us, "GyrX": 0.1, "GyrY": 0.0,
                             "GyrZ": 0.0}))
        rows.append(("ACC", {"TimeUS": us, "I": 0, "SampleUS": us, "AccX": 0.0, "AccY": 0.0,
                             "AccZ": -9.8}))
        rows.append(("RATE", {"TimeUS": us, "R": 1.0, "P": 2.0, "Y": 3.0}))
        if j % 10 == 0:
            rows.append(("RCOU", {"TimeUS": us, "C1": 1300 + j, "C2": 1400 - j, "C3": 1350,
                                  "C4": 1360 + j}))
            rows.append(("ESC", {"TimeUS": us, "Instance": 0, "RPM": 5000.0 + j}))
    for n, kind in enumerate((ISB_ACCEL, ISB_GYRO)):
        rows.append(("ISBH", {"TimeUS": round(_T0 * 1e6), "N": n, "type": kind, "instance": 0,
                              "mul": 200, "smp_cnt": 64, "SampleUS": round(_T0 * 1e6),
                              "smp_rate": 1000.0}))
        for seqno in range(2):
            block = np.arange(32, dtype="<i2").tobytes()
            rows.append(("ISBD", {"TimeUS": round(_T0 * 1e6) + seqno, "N": n, "seqno": seqno,
                                  "x": block, "y": block, "z": block}))
    imu = [r for r in rows if r[0] in ("IMU", "GYR", "ACC", "RATE", "ISBH", "ISBD")]
    from pymavlink.DFReader import DFFormat

    for _ in range(int(rng.integers(1, 40))):
        name, values = imu[int(rng.integers(0, len(imu)))]
        tid, fmt, columns = DATAFLASH_FORMATS[name]
        layout = DFFormat(tid, name, 0, fmt, columns)
        numeric = [(c, k) for c, k in zip(layout.columns, fmt, strict=True) if k in _DF_CODES]
        column, kind = numeric[int(rng.integers(0, len(numeric)))]
        values[column] = _extreme(rng, _DF_CODES[kind])
    return rows


def _write_dataflash(path: Path, rng: np.random.Generator) -> None:
    write_dataflash(path, DATAFLASH_FORMATS, _dataflash_rows(rng))


# --- ULog ------------------------------------------------------------------------------------


def _write_ulog(path: Path, rng: np.random.Generator) -> None:
    t = _T0 + np.arange(100) / 250.0
    topics: dict[str, list[dict[str, float]]] = {
        "sensor_combined": [{"timestamp": round(ti * 1e6), "gyro_rad[0]": 0.1,
                             "accelerometer_m_s2[2]": -9.8,
                             "accelerometer_timestamp_relative": 100} for ti in t],
        "vehicle_angular_velocity": [{"timestamp": round(ti * 1e6),
                                      "timestamp_sample": round(ti * 1e6), "xyz[0]": 0.2}
                                     for ti in t[::2]],
        "actuator_outputs": [{"timestamp": round(ti * 1e6), "noutputs": 4,
                              **{f"output[{i}]": 1300.0 + j + i for i in range(4)}}
                             for j, ti in enumerate(t[::10])],
        "esc_status": [{"timestamp": round(ti * 1e6), "esc_count": 4,
                        **{f"esc[{i}].esc_rpm": 5000 for i in range(4)}} for ti in t[::25]],
    }
    codes = {"timestamp": "Q", "timestamp_sample": "Q", "accelerometer_timestamp_relative": "i",
             "gyro_integral_dt": "I", "accelerometer_integral_dt": "I"}
    for _ in range(int(rng.integers(1, 40))):
        name = str(rng.choice(["sensor_combined", "vehicle_angular_velocity"]))
        row = topics[name][int(rng.integers(0, len(topics[name])))]
        field = str(rng.choice(list(row) + ["gyro_rad[1]", "accelerometer_m_s2[0]", "xyz[2]"]))
        if name == "vehicle_angular_velocity" and field.startswith(("gyro", "acc")):
            field = "xyz[1]"
        if name == "sensor_combined" and field.startswith("xyz"):
            field = "gyro_rad[2]"
        row[field] = _extreme(rng, codes.get(field, "f"))
    write_ulog(path, ULOG_FORMATS, topics, parameters={"IMU_INTEG_RATE": int(rng.integers(-5, 500)),
                                                "IMU_GYRO_CUTOFF": float(rng.choice(_FLOATS))})


# --- tlog ------------------------------------------------------------------------------------


def _write_tlog(path: Path, rng: np.random.Generator) -> None:
    from pymavlink.dialects.v20 import ardupilotmega as m

    t = _T0 + np.arange(80) / 50.0
    autopilot = int(rng.choice([m.MAV_AUTOPILOT_ARDUPILOTMEGA, m.MAV_AUTOPILOT_PX4]))

    def fuzzed(cls: Any, *args: Any) -> Any:
        values = list(args)
        if rng.random() < 0.3:
            i = int(rng.integers(0, len(values)))
            value = values[i]  # the field's type told by its clean value
            values[i] = (_extreme(rng, "f") if isinstance(value, float)
                         else _extreme(rng, "h" if abs(value) < 2**15 else "I"))
        try:
            return cls(*values)
        except (struct.error, TypeError, ValueError):
            return cls(*args)

    messages = [(_T0 - 1.0, m.MAVLink_heartbeat_message(2, autopilot, 0, 0, 4, 3))]
    for j, ti in enumerate(t):
        ms, us = round(ti * 1e3), round(ti * 1e6)
        messages += [
            (ti, fuzzed(m.MAVLink_highres_imu_message, us, 0.1, 0.2, -9.8, 0.01, 0.02, 0.03,
                        0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0, 0b111111, 0)),
            (ti, fuzzed(m.MAVLink_scaled_imu_message, ms, 10, 20, -1000, 1, 2, 3, 0, 0, 0, 0)),
            (ti, fuzzed(m.MAVLink_raw_imu_message, us, 10, 20, -1000, 1, 2, 3, 0, 0, 0, 0, 0)),
            (ti, fuzzed(m.MAVLink_attitude_message, ms, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3)),
            (ti, m.MAVLink_servo_output_raw_message(us, 0, 1300 + j, 1400, 1350 - j, 1360,
                                                    0, 0, 0, 0)),
        ]
    with path.open("wb") as out:
        mav = m.MAVLink(out, srcSystem=1, srcComponent=1)
        for ti, msg in messages:
            out.write(struct.pack(">Q", round((1.7e9 + ti) * 1e6)))
            with contextlib.suppress(struct.error, OverflowError):
                mav.send(msg)


_WRITERS: dict[str, tuple[Callable[[Path, np.random.Generator], None],
                          Callable[..., ParsedLog]]] = {
    ".bin": (_write_dataflash, read_dataflash), ".ulg": (_write_ulog, read_ulog),
    ".tlog": (_write_tlog, read_tlog)}


@pytest.mark.parametrize("suffix", list(_WRITERS))
def test_fuzzed_imu_messages_read_or_refused_in_one_line(
        suffix: str, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """40 seeded cases per format: IMU fields to extremes, half of them with their bytes
    mutated too."""
    write, read = _WRITERS[suffix]
    vehicle = load_vehicle("sitl_quad")
    rng = np.random.default_rng({".bin": 1, ".ulg": 2, ".tlog": 3}[suffix])
    bytewise = [b for b in BYTE_MUTATIONS if b not in ("none", "huge", "words", "junk_tail")]
    outcomes = []
    for case in range(40):
        path = tmp_path / f"c{case}{suffix}"
        write(path, rng)
        if case % 2:
            path.write_bytes(BYTE_MUTATIONS[str(rng.choice(bytewise))](path.read_bytes(), rng))
        try:
            log = read(path, vehicle)
        except (LogFormatError, InputError) as exc:
            assert "\n" not in str(exc) and str(path) in str(exc), exc
            outcomes.append("refused")
            continue
        for series in (log.gyro, log.accel):
            if series is not None:
                assert series.values.shape == (series.t.size, 3), (case, series.label)
        outcomes.append("read")
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out[-300:], err[-300:])
    assert "read" in outcomes  # the IMU fuzz alone leaves most logs readable
