"""The IMU, motor outputs and ESC speeds of each autopilot log format, read into `ParsedLog`.

Each format is written with a known gyro (rad/s) and specific force (m/s²), body FRD, in
the encoding its autopilot uses (DataFlash IMU/GYR/ACC/ISBD/RATE, ULog sensor_combined
and vehicle_angular_velocity, MAVLink HIGHRES_IMU/SCALED_IMU/RAW_IMU/ATTITUDE), and read
back to within the encoding's resolution; the real logs of ``../shared/real-logs`` are
read and checked for physical sense.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.formats.dataflash import ISB_ACCEL, ISB_GYRO, read_dataflash, write_dataflash
from mavsysid.formats.parsed_log import ParsedLog
from mavsysid.formats.tlog import STANDARD_GRAVITY, read_tlog
from mavsysid.formats.ulog import read_ulog, write_ulog
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

T0 = 30.0  # s since boot at the first sample


@pytest.fixture(scope="module")
def quad() -> VehicleConfig:
    return load_vehicle("sitl_quad")


def _imu_truth(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A gyro (rad/s) and specific force (m/s²), body FRD, smooth in t (s)."""
    w = np.column_stack([0.8 * np.sin(3.0 * t), -0.5 * np.cos(2.0 * t), 0.3 * np.sin(t)])
    f = np.column_stack([1.5 * np.sin(2.5 * t), -1.0 * np.cos(1.5 * t),
                         -9.81 + 2.0 * np.sin(4.0 * t)])
    return w, f


def _check(series: Any, tolerance: float, which: int, label: str) -> None:
    """``series`` holds the truth's gyro (which 0) or specific force (1) at its times."""
    assert series is not None and series.label.startswith(label), series
    np.testing.assert_allclose(series.values, _imu_truth(series.t)[which], atol=tolerance)


# --- DataFlash -------------------------------------------------------------------------------

DATAFLASH_FORMATS = {
    "PARM": (64, "QNff", "TimeUS,Name,Value,Default"),
    "IMU": (65, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"),
    "GYR": (66, "QBQfff", "TimeUS,I,SampleUS,GyrX,GyrY,GyrZ"),
    "ACC": (67, "QBQfff", "TimeUS,I,SampleUS,AccX,AccY,AccZ"),
    "ISBH": (68, "QHBBHHQf", "TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate"),
    "ISBD": (69, "QHHaaa", "TimeUS,N,seqno,x,y,z"),
    "RATE": (70, "Qffffffffffff", "TimeUS,RDes,R,ROut,PDes,P,POut,YDes,Y,YOut,ADes,A,AOut"),
    "ESC": (71, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
    "RCOU": (72, "QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14"),
}
# ArduCopter 3.5/3.6: IMU of instance 0, IMU2 of instance 1, no I field.
_IMU_3X = "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"
DATAFLASH_FORMATS_3X = {"IMU": (65, "QffffffIIfBBHH", _IMU_3X),
                        "IMU2": (73, "QffffffIIfBBHH", _IMU_3X),
                        "RCOU": DATAFLASH_FORMATS["RCOU"]}


def _motor_rows(t: np.ndarray) -> list[tuple[str, dict[str, Any]]]:
    """RCOU at the given times (four motors moving, a servo still) and ESC rpm at half."""
    rows: list[tuple[str, dict[str, Any]]] = []
    for j, ti in enumerate(t):
        pwm = [1400 + j % 50 + 10 * i for i in range(4)]
        rows.append(("RCOU", {"TimeUS": round(ti * 1e6), **{f"C{i + 1}": v for i, v
                                                           in enumerate(pwm)}, "C5": 1500}))
    return rows


def _imu_rows(t: np.ndarray, old: bool = False) -> list[tuple[str, dict[str, Any]]]:
    w, f = _imu_truth(t)
    rows = []
    for instance in (1, 0):  # instance 1 is another IMU, never read
        for ti, wi, fi in zip(t, w, f, strict=True):
            values = {"TimeUS": round(ti * 1e6), **dict(zip(("GyrX", "GyrY", "GyrZ"),
                                                            wi + instance, strict=True)),
                      **dict(zip(("AccX", "AccY", "AccZ"), fi + instance, strict=True))}
            if old:
                rows.append(("IMU2" if instance else "IMU", values))
            else:
                rows.append(("IMU", {**values, "I": instance}))
    return rows


def _parm(values: dict[str, float]) -> list[tuple[str, dict[str, Any]]]:
    return [("PARM", {"TimeUS": 1000, "Name": name.encode(), "Value": value, "Default": 0.0})
            for name, value in values.items()]


def test_dataflash_imu_of_instance_0_with_its_position_and_filter(tmp_path: Path,
                                                                  quad: VehicleConfig) -> None:
    t = T0 + np.arange(200) / 400.0
    rows = _parm({"INS_POS1_X": 0.05, "INS_POS1_Y": -0.02, "INS_POS1_Z": 0.01,
                  "INS_GYRO_FILTER": 20.0, "INS_ACCEL_FILTER": 10.0})
    rows += _imu_rows(t) + _motor_rows(t[::40])
    write_dataflash(tmp_path / "a.bin", DATAFLASH_FORMATS, rows)
    log = read_dataflash(tmp_path / "a.bin", quad)
    _check(log.gyro, 1e-6, 0, "IMU GyrX")
    _check(log.accel, 1e-5, 1, "IMU AccX")
    assert log.gyro.values.shape == (200, 3)
    assert log.imu_position == pytest.approx((0.05, -0.02, 0.01))
    assert (log.imu_filter.gyro_cutoff_hz, log.imu_filter.accel_cutoff_hz) == (20.0, 10.0)
    # Motor outputs as logged, the still servo (C5) left out; no ESC rpm.
    assert log.motor_outputs.kind == "pwm" and log.motor_outputs.series.values.shape == (5, 4)
    assert log.esc_speeds == ()


def test_dataflash_older_imu_messages_by_name(tmp_path: Path, quad: VehicleConfig) -> None:
    t = T0 + np.arange(100) / 50.0
    write_dataflash(tmp_path / "old.bin", DATAFLASH_FORMATS_3X,
                    _imu_rows(t, old=True) + _motor_rows(t[::5]))
    log = read_dataflash(tmp_path / "old.bin", quad)
    _check(log.gyro, 1e-6, 0, "IMU GyrX")
    _check(log.accel, 1e-5, 1, "IMU AccX")
    assert log.imu_position is None and log.imu_filter is None


def test_dataflash_raw_gyr_acc_at_their_sample_times_over_imu(tmp_path: Path,
                                                               quad: VehicleConfig) -> None:
    """GYR/ACC (raw IMU logging) win over IMU; their SampleUS is when the sensor sampled."""
    t = T0 + np.arange(400) / 1000.0
    w, f = _imu_truth(t)
    rows = _parm({"INS_GYRO_FILTER": 20.0}) + _imu_rows(t[::10]) + _motor_rows(t[::100])
    for ti, wi, fi in zip(t, w, f, strict=True):
        written = round(ti * 1e6) + 700  # logged 0.7 ms after sampling
        rows.append(("GYR", {"TimeUS": written, "I": 0, "SampleUS": round(ti * 1e6),
                             **dict(zip(("GyrX", "GyrY", "GyrZ"), wi, strict=True))}))
        rows.append(("ACC", {"TimeUS": written, "I": 0, "SampleUS": round(ti * 1e6),
                             **dict(zip(("AccX", "AccY", "AccZ"), fi, strict=True))}))
    write_dataflash(tmp_path / "raw.bin", DATAFLASH_FORMATS, rows)
    log = read_dataflash(tmp_path / "raw.bin", quad)
    _check(log.gyro, 1e-6, 0, "GYR")
    _check(log.accel, 1e-5, 1, "ACC")
    assert log.gyro.t.size == 400
    # Raw samples: before the INS_GYRO_FILTER low-pass.
    assert log.imu_filter.gyro_cutoff_hz == 0.0 and log.imu_filter.accel_cutoff_hz == 0.0


def _isb_rows(kind: int, number: int, start: float, rate: float, mul: int,
              count: int = 64) -> list[tuple[str, dict[str, Any]]]:
    """One batch: ISBH, then ISBD of 32 samples per axis (int16 of value × mul)."""
    t = start + np.arange(count) / rate
    values = _imu_truth(t)[0 if kind == ISB_GYRO else 1]
    stamp = round(start * 1e6) + 50_000
    rows = [("ISBH", {"TimeUS": stamp, "N": number, "type": kind, "instance": 0, "mul": mul,
                      "smp_cnt": count, "SampleUS": round(start * 1e6), "smp_rate": rate})]
    for seqno in range(count // 32):
        block = np.rint(values[32 * seqno:32 * seqno + 32] * mul).astype("<i2")
        rows.append(("ISBD", {"TimeUS": stamp + 10 + seqno, "N": number, "seqno": seqno,
                              **{axis: block[:, a].tobytes() for a, axis in enumerate("xyz")}}))
    return rows


def test_dataflash_batch_sampler_scaled_by_its_multiplier(tmp_path: Path,
                                                          quad: VehicleConfig) -> None:
    # ArduPilot's default multipliers: INT16_MAX / 16 g (accel), INT16_MAX / 2000 deg/s.
    accel_mul, gyro_mul = round(32767 / (16 * 9.80665)), round(32767 / np.radians(2000.0))
    rows = _parm({"INS_LOG_BAT_OPT": 0.0})
    rows += _isb_rows(ISB_ACCEL, 0, T0, 1000.0, accel_mul)
    rows += _isb_rows(ISB_GYRO, 1, T0 + 0.2, 1000.0, gyro_mul)
    rows += _isb_rows(ISB_ACCEL, 2, T0 + 0.4, 1000.0, accel_mul)
    write_dataflash(tmp_path / "isb.bin", DATAFLASH_FORMATS,
                    rows + _motor_rows(T0 + np.arange(5) * 0.1))
    log = read_dataflash(tmp_path / "isb.bin", quad)
    _check(log.gyro, 0.6 / gyro_mul, 0, "ISBD")
    _check(log.accel, 0.6 / accel_mul, 1, "ISBD")
    assert log.gyro.t.size == 64 and log.accel.t.size == 128  # two accel batches
    assert np.diff(log.accel.t)[0] == pytest.approx(1e-3)
    assert log.imu_filter.gyro_cutoff_hz == 0.0


def test_dataflash_rate_message_is_the_gyro_without_imu_messages(tmp_path: Path,
                                                                 quad: VehicleConfig) -> None:
    t = T0 + np.arange(100) / 400.0
    w = _imu_truth(t)[0]
    rows = [("RATE", {"TimeUS": round(ti * 1e6), "R": float(np.degrees(wi[0])),
                      "P": float(np.degrees(wi[1])), "Y": float(np.degrees(wi[2]))})
            for ti, wi in zip(t, w, strict=True)]
    write_dataflash(tmp_path / "rate.bin", DATAFLASH_FORMATS, rows + _motor_rows(t[::10]))
    log = read_dataflash(tmp_path / "rate.bin", quad)
    _check(log.gyro, 1e-6, 0, "RATE")
    assert log.accel is None


def test_dataflash_keeps_motor_outputs_and_sparse_esc_rpm_both(tmp_path: Path,
                                                               quad: VehicleConfig) -> None:
    """ESC rpm at 2 Hz still reads as the rotor speeds and as esc_speeds; RCOU stays raw,
    a value outside the PWM range included."""
    t = T0 + np.arange(40) / 10.0
    rows = _motor_rows(t)
    rows[3][1]["C2"] = 2300  # beyond any PWM range: kept as logged
    for ti in t[::5]:
        for i in range(4):
            rows.append(("ESC", {"TimeUS": round(ti * 1e6) + i, "Instance": i,
                                 "RPM": 6000.0 + 100 * i}))
    rows.sort(key=lambda row: row[1]["TimeUS"])
    write_dataflash(tmp_path / "esc.bin", DATAFLASH_FORMATS, rows)
    log = read_dataflash(tmp_path / "esc.bin", quad)
    assert len(log.esc_speeds) == 4 and log.esc_speeds[1].t.size == 8
    assert log.esc_speeds[1].values[0, 0] == pytest.approx(6100.0 * 2 * np.pi / 60.0)
    assert [r.label for r in log.rotors] == [e.label for e in log.esc_speeds]
    assert log.motor_outputs.series.values[3, 1] == 2300.0


# --- ULog ------------------------------------------------------------------------------------

ULOG_FORMATS = {
    "sensor_combined": "uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;"
                       "int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;"
                       "uint32_t accelerometer_integral_dt;",
    "vehicle_angular_velocity": "uint64_t timestamp;uint64_t timestamp_sample;float[3] xyz;",
    "vehicle_acceleration": "uint64_t timestamp;uint64_t timestamp_sample;float[3] xyz;",
    "actuator_outputs": "uint64_t timestamp;uint32_t noutputs;float[16] output;",
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;",
    "esc_status": "uint64_t timestamp;uint8_t esc_count;esc_report[8] esc;",
}


def _vector_row(prefix: str, v: np.ndarray) -> dict[str, float]:
    return {f"{prefix}[{i}]": float(x) for i, x in enumerate(v)}


def _combined_rows(t: np.ndarray, relative_us: int) -> list[dict[str, float]]:
    w = _imu_truth(t)[0]
    f = _imu_truth(t + relative_us * 1e-6)[1]
    rows = [{"timestamp": round(ti * 1e6), "accelerometer_timestamp_relative": relative_us,
             **_vector_row("gyro_rad", wi), **_vector_row("accelerometer_m_s2", fi)}
            for ti, wi, fi in zip(t, w, f, strict=True)]
    rows[5]["accelerometer_timestamp_relative"] = 0x7FFFFFFF  # no accelerometer sample
    return rows


def _ulog_motor_topics(t: np.ndarray) -> dict[str, list[dict[str, float]]]:
    outputs = [{"timestamp": round(ti * 1e6), "noutputs": 8,
                **{f"output[{i}]": 1300.0 + 10 * i + j % 7 for i in range(4)}}
               for j, ti in enumerate(t)]
    esc = [{"timestamp": round(ti * 1e6), "esc_count": 4,
            **{f"esc[{i}].esc_rpm": 5000 + 10 * i for i in range(4)}} for ti in t[::10]]
    return {"actuator_outputs": outputs, "esc_status": esc}


def test_ulog_sensor_combined_with_the_accelerometer_at_its_own_time(
        tmp_path: Path, quad: VehicleConfig) -> None:
    t = T0 + np.arange(250) / 250.0
    topics = {"sensor_combined": _combined_rows(t, -1500), **_ulog_motor_topics(t[::25])}
    write_ulog(tmp_path / "c.ulg", ULOG_FORMATS, topics, parameters={
        "EKF2_IMU_POS_X": 0.03, "EKF2_IMU_POS_Y": 0.0, "EKF2_IMU_POS_Z": -0.02,
        "IMU_INTEG_RATE": 250, "IMU_GYRO_CUTOFF": 40.0, "IMU_ACCEL_CUTOFF": 30.0})
    log = read_ulog(tmp_path / "c.ulg", quad)
    _check(log.gyro, 1e-6, 0, "sensor_combined gyro_rad")
    _check(log.accel, 1e-5, 1, "sensor_combined accelerometer_m_s2")
    assert log.gyro.t.size == 250 and log.accel.t.size == 249  # the invalid one left out
    assert log.accel.t[0] == pytest.approx(t[0] - 1.5e-3)
    assert log.imu_position == pytest.approx((0.03, 0.0, -0.02))
    # sensor_combined integrates raw samples: none of the IMU_*_CUTOFF low-passes.
    assert (log.imu_filter.gyro_cutoff_hz, log.imu_filter.accel_cutoff_hz) == (0.0, 0.0)
    assert log.motor_outputs.kind == "pwm" and log.motor_outputs.series.values.shape == (10, 4)
    # One rpm sample is too sparse to be the rotor speeds, but it is kept.
    (esc,) = log.esc_speeds
    assert esc.t.size == 1 and [r.label for r in log.rotors] == ["actuator_outputs PWM"]


def test_ulog_faster_filtered_gyro_is_read_with_its_cutoff(tmp_path: Path,
                                                           quad: VehicleConfig) -> None:
    slow, fast = T0 + np.arange(100) / 100.0, T0 + np.arange(400) / 400.0
    w = _imu_truth(fast)[0]
    velocity = [{"timestamp": round(ti * 1e6) + 300, "timestamp_sample": round(ti * 1e6),
                 **_vector_row("xyz", wi)} for ti, wi in zip(fast, w, strict=True)]
    f = _imu_truth(slow)[1]
    acceleration = [{"timestamp": round(ti * 1e6), "timestamp_sample": round(ti * 1e6),
                     **_vector_row("xyz", fi)} for ti, fi in zip(slow, f, strict=True)]
    topics = {"sensor_combined": _combined_rows(slow, 0), "vehicle_angular_velocity": velocity,
              "vehicle_acceleration": acceleration, **_ulog_motor_topics(slow[::10])}
    write_ulog(tmp_path / "f.ulg", ULOG_FORMATS, topics, parameters={
        "IMU_INTEG_RATE": 100, "IMU_GYRO_CUTOFF": 40.0, "IMU_ACCEL_CUTOFF": 30.0})
    log = read_ulog(tmp_path / "f.ulg", quad)
    _check(log.gyro, 1e-6, 0, "vehicle_angular_velocity")
    _check(log.accel, 1e-5, 1, "sensor_combined")  # equal rates: sensor_combined
    assert (log.imu_filter.gyro_cutoff_hz, log.imu_filter.accel_cutoff_hz) == (40.0, 0.0)
    assert log.imu_position is None


# --- tlog ------------------------------------------------------------------------------------


def _tlog(path: Path, messages: list[tuple[float, Any]], autopilot: int) -> None:
    """Autopilot messages at their boot time (s), received 5 ms later, after a HEARTBEAT."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    epoch = 1.7e9
    with path.open("wb") as out:
        mav = m.MAVLink(out, srcSystem=1, srcComponent=1)

        def send(t: float, msg: Any) -> None:
            out.write(struct.pack(">Q", round((epoch + t + 0.005) * 1e6)))
            mav.send(msg)

        send(T0 - 1.0, m.MAVLink_heartbeat_message(2, autopilot, 0, 0, 4, 3))
        for t, msg in messages:
            send(t, msg)


def _tlog_motors(t: np.ndarray) -> list[tuple[float, Any]]:
    from pymavlink.dialects.v20 import ardupilotmega as m

    return [(ti, m.MAVLink_servo_output_raw_message(round(ti * 1e6), 0,
                                                   *[1300 + j % 9 + 5 * i for i in range(4)],
                                                   0, 0, 0, 0)) for j, ti in enumerate(t)]


def _scaled_messages(cls: Any, t: np.ndarray, microseconds: bool = False,
                     **extra: int) -> list[tuple[float, Any]]:
    w, f = _imu_truth(t)
    gyro = np.rint(w * 1e3).astype(int)
    acc = np.rint(f / STANDARD_GRAVITY * 1e3).astype(int)
    return [(ti, cls(round(ti * (1e6 if microseconds else 1e3)), *a.tolist(), *g.tolist(),
                     0, 0, 0, **extra)) for ti, g, a in zip(t, gyro, acc, strict=True)]


def _read_tlog(path: Path, messages: list[tuple[float, Any]], autopilot: int) -> ParsedLog:
    t = T0 + np.arange(20) / 10.0
    _tlog(path, sorted(messages + _tlog_motors(t), key=lambda pair: pair[0]), autopilot)
    return read_tlog(path, load_vehicle("sitl_quad"))


def test_tlog_highres_imu_rows_flagged_per_sensor(tmp_path: Path) -> None:
    from pymavlink.dialects.v20 import ardupilotmega as m

    t = T0 + np.arange(200) / 100.0
    w, f = _imu_truth(t)
    messages = []
    for j, (ti, wi, fi) in enumerate(zip(t, w, f, strict=True)):
        flags = 0b111111 if j % 2 == 0 else 0b000111  # every other row: accelerometer only
        gyro = wi if j % 2 == 0 else wi + 5.0  # a stale gyro on those rows, never read
        messages.append((ti, m.MAVLink_highres_imu_message(round(ti * 1e6), *fi, *gyro, 0, 0, 0,
                                                           0, 0, 0, 0, flags, 0)))
    log = _read_tlog(tmp_path / "h.tlog", messages, m.MAV_AUTOPILOT_PX4)
    _check(log.gyro, 1e-6, 0, "HIGHRES_IMU")
    _check(log.accel, 1e-5, 1, "HIGHRES_IMU")
    assert log.gyro.t.size == 100 and log.accel.t.size == 200
    assert log.motor_outputs.kind == "pwm" and log.motor_outputs.series.values.shape == (20, 4)


def test_tlog_ardupilot_raw_imu_in_milli_units_with_its_parameters(tmp_path: Path) -> None:
    from pymavlink.dialects.v20 import ardupilotmega as m

    t = T0 + np.arange(100) / 50.0
    messages = _scaled_messages(m.MAVLink_raw_imu_message, t, microseconds=True, id=0,
                                temperature=4000)
    messages += [(T0 - 0.5, m.MAVLink_param_value_message(name.encode(), value, 9, 900, i))
                 for i, (name, value) in enumerate([("INS_POS1_X", 0.04), ("INS_POS1_Y", 0.0),
                                                    ("INS_POS1_Z", 0.0),
                                                    ("INS_GYRO_FILTER", 20.0)])]
    log = _read_tlog(tmp_path / "r.tlog", messages, m.MAV_AUTOPILOT_ARDUPILOTMEGA)
    _check(log.gyro, 0.6e-3, 0, "RAW_IMU")
    _check(log.accel, 0.6e-3 * STANDARD_GRAVITY, 1, "RAW_IMU")
    assert log.imu_position == pytest.approx((0.04, 0.0, 0.0))
    assert log.imu_filter.gyro_cutoff_hz == 20.0 and log.imu_filter.accel_cutoff_hz is None


def test_tlog_raw_imu_of_another_autopilot_is_not_read(tmp_path: Path) -> None:
    """Outside ArduPilot RAW_IMU holds raw sensor counts: the IMU falls to SCALED_IMU2,
    and to the ATTITUDE rates without it, each said in a note."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    t = T0 + np.arange(100) / 50.0
    raw = _scaled_messages(m.MAVLink_raw_imu_message, t, microseconds=True, id=0,
                           temperature=0)
    second = _scaled_messages(m.MAVLink_scaled_imu2_message, t, temperature=0)
    log = _read_tlog(tmp_path / "s.tlog", raw + second, m.MAV_AUTOPILOT_PX4)
    _check(log.gyro, 0.6e-3, 0, "SCALED_IMU2")
    assert any("SCALED_IMU2" in note for note in log.notes)
    w = _imu_truth(t)[0]
    attitude = [(ti, m.MAVLink_attitude_message(round(ti * 1e3), 0.0, 0.0, 0.0, *wi))
                for ti, wi in zip(t, w, strict=True)]
    log = _read_tlog(tmp_path / "a.tlog", raw + attitude, m.MAV_AUTOPILOT_PX4)
    _check(log.gyro, 1e-6, 0, "ATTITUDE")
    assert log.accel is None and any("raw sensor counts" in note for note in log.notes)


def test_tlog_scaled_imu_is_the_primary_imu(tmp_path: Path) -> None:
    from pymavlink.dialects.v20 import ardupilotmega as m

    t = T0 + np.arange(100) / 50.0
    first = _scaled_messages(m.MAVLink_scaled_imu_message, t, temperature=0)
    second = [(ti, m.MAVLink_scaled_imu2_message(round(ti * 1e3), 0, 0, 0, 9, 9, 9, 0, 0, 0, 0))
              for ti in t]
    log = _read_tlog(tmp_path / "p.tlog", first + second, m.MAV_AUTOPILOT_PX4)
    _check(log.gyro, 0.6e-3, 0, "SCALED_IMU ")
    _check(log.accel, 0.6e-3 * STANDARD_GRAVITY, 1, "SCALED_IMU ")
    assert log.notes == ()


# --- the real logs ---------------------------------------------------------------------------

_REAL = Path(__file__).resolve().parents[3] / "shared" / "real-logs"
_REAL_LOGS = [
    # file, gyro message, accel message, gyro rate, accel rate (Hz, median)
    ("ardupilot-test.BIN", "IMU GyrX", "IMU AccX", 50.0, 50.0),
    ("px4-sample.ulg", "sensor_combined", "sensor_combined", 250.0, 250.0),
    ("px4-sample_appended_multiple.ulg", "sensor_combined", "sensor_combined", 250.0, 250.0),
    ("px4-sample_log_small.ulg", "vehicle_angular_velocity", "sensor_combined", 409.0, 204.6),
    ("px4-sample_logging_tagged_and_default_params.ulg", "sensor_combined", "sensor_combined",
     250.0, 250.0),
    ("px4-sample_px4_events.ulg", "sensor_combined", "sensor_combined", 250.0, 250.0),
]


@pytest.mark.skipif(not _REAL.is_dir(), reason="../shared/real-logs not present")
@pytest.mark.parametrize(("name", "gyro", "accel", "gyro_hz", "accel_hz"), _REAL_LOGS)
def test_real_logs_hold_a_physical_imu(name: str, gyro: str, accel: str, gyro_hz: float,
                                       accel_hz: float, quad: VehicleConfig) -> None:
    """The primary IMU of each real log: its message and rate, a specific force of
    9.81 m/s² ± 2 % averaged over the first second (on the ground, or hovering) and a
    gyro of less than 0.1 rad/s on average there."""
    path = _REAL / name
    log = (read_dataflash if path.suffix == ".BIN" else read_ulog)(path, quad)
    for series, label, rate in ((log.gyro, gyro, gyro_hz), (log.accel, accel, accel_hz)):
        assert series.label.startswith(label)
        assert 1.0 / np.median(np.diff(series.t)) == pytest.approx(rate, rel=0.01)
    first = log.accel.t < log.accel.t[0] + 1.0
    assert np.linalg.norm(log.accel.values[first].mean(axis=0)) == pytest.approx(9.81, rel=0.02)
    assert log.accel.values[first, 2].mean() < -9.0  # z down: −g on z_FRD, level
    first = log.gyro.t < log.gyro.t[0] + 1.0
    assert np.linalg.norm(log.gyro.values[first].mean(axis=0)) < 0.1
