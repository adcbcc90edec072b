"""A simulated flight written as ArduCopter writes its DataFlash log (``.bin``).

What ArduCopter 4.5 logs of the flight and when; the messages themselves (fields, units,
frames) are `mavsysid.formats.dataflash`'s `ARDUPILOT_MESSAGES`:

- ``MSG`` (firmware string) and ``PARM`` (e.g. FRAME_CLASS, FRAME_TYPE) at the start;
- ``MODE`` at each mode change: LOITER for the take-off, GUIDED for the calibration part
  (what ``mavsysid stream`` commands), LAND;
- ``XKF1`` (EKF3 core 0: attitude, velocity, position, NED) and ``XKQ`` (its quaternion)
  at 25 Hz, from Copter's 25 Hz logging loop with LOG_BITMASK's ATTITUDE_FAST;
- ``ESC`` per instance (RPM): ESC telemetry or bidirectional DShot, one message per ESC
  and update, each ESC a little after the previous one;
- ``RCOU`` C1..C14 PWM at 10 Hz, the commanded rotor speeds through the vehicle's
  `[motor]` curve;
- ``IMU`` of instance 0 (gyro rad/s, specific force m/s², body FRD), the flight's IMU
  samples through ArduPilot's 2-pole low-pass at INS_GYRO_FILTER / INS_ACCEL_FILTER
  (20 Hz by default, `lowpass`), at 25 Hz (Copter's 25 Hz logging loop with LOG_BITMASK's
  IMU bit, the default) or the loop rate, 400 Hz, with IMU_FAST
  (``Copter::loop_rate_logging``); with ``PARM`` INS_GYRO_FILTER, INS_ACCEL_FILTER and
  INS_POS1_X/Y/Z (the IMU's position, m, body FRD) when the flight states it.

ESC instance i and output C(i + 1) are the autopilot's motor i + 1, mapped to the config's
rotors by ``motor_order``. TimeUS is µs since boot; the flight starts ``boot_time`` after
boot.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES
from mavsysid.flight.offline.autopilot_log import (
    LoggedFlight,
    check_motor_order,
    lowpass,
    microsecond_stamp,
    sample_indices,
)
from mavsysid.formats.dataflash import (
    ARDUPILOT_MESSAGES,
    MODE_REASONS,
    RCOU_OUTPUTS,
    write_dataflash,
)
from mavsysid.formats.motor_curve import pwm_from_rotor_speed
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import enu_to_ned, flu_to_frd, quaternion_enu_to_ned
from mavsysid.vehicle.rotation import quat_to_euler

Stamp = Callable[[float], int]  # flight time, s → log time, µs since boot

__all__ = ["ArduPilotLogSettings", "write_ardupilot_log"]

#: A data message: its name and its values by column.
Message = tuple[str, dict[str, Any]]


@dataclass(frozen=True)
class ArduPilotLogSettings:
    """Rates and clock of the written log.

    Attributes
    ----------
    ekf_rate, esc_rate, rcou_rate : float
        Hz: XKF1/XKQ (25 with ATTITUDE_FAST), ESC rpm per instance, RCOU (10).
    imu_rate : float
        Hz of IMU: 25 (LOG_BITMASK's IMU, the default) or 400 (IMU_FAST, the loop rate);
        at most the flight's own rate is met.
    gyro_filter_hz, accel_filter_hz : float
        INS_GYRO_FILTER and INS_ACCEL_FILTER, Hz (ArduPilot's defaults 20; 0: none).
    boot_time : float
        s from the autopilot's boot to the flight's t = 0.
    firmware : str
        The ``MSG`` firmware line.
    """

    ekf_rate: float = 25.0
    esc_rate: float = 50.0
    rcou_rate: float = 10.0
    imu_rate: float = 25.0
    gyro_filter_hz: float = 20.0
    accel_filter_hz: float = 20.0
    boot_time: float = 30.0
    firmware: str = "ArduCopter V4.5.7 (mavsysid simulation)"


def _mode_rows(flight: LoggedFlight, stamp: Stamp) -> list[Message]:
    """MODE at each change: LOITER for the take-off (the pilot's), GUIDED for the
    calibration part and LAND (the ground station's), or the flight's own mode changes."""
    rows: list[Message] = []
    for t, name in flight.modes(("LOITER", "GUIDED", "LAND")):
        reason = "RC_COMMAND" if name in ("LOITER", "STABILIZE") else "GCS_COMMAND"
        number = ARDUCOPTER_MODES.get(name)
        if number is not None:
            rows.append(("MODE", {"TimeUS": stamp(t), "Mode": number, "ModeNum": number,
                                  "Rsn": MODE_REASONS[reason]}))
    return rows


def _ekf_rows(flight: LoggedFlight, rate: float, stamp: Stamp) -> list[Message]:
    """XKF1 and XKQ of core 0 at ``rate``."""
    i = sample_indices(flight.t, rate, phase=0.002)
    position, velocity = enu_to_ned(flight.position[i]), enu_to_ned(flight.velocity[i])
    q = quaternion_enu_to_ned(flight.quaternion[i])
    roll, pitch, yaw = np.degrees(quat_to_euler(q)).T
    rows: list[Message] = []
    for j, t in enumerate(flight.t[i]):
        us = stamp(t)
        rows.append(("XKF1", {
            "TimeUS": us, "C": 0, "Roll": round(roll[j] * 100), "Pitch": round(pitch[j] * 100),
            "Yaw": round((yaw[j] % 360.0) * 100) % 36000,  # centidegrees, [0, 360)
            **dict(zip(("VN", "VE", "VD"), velocity[j], strict=True)),
            **dict(zip(("PN", "PE", "PD"), position[j], strict=True))}))
        rows.append(("XKQ", {"TimeUS": us, "C": 0,
                             **dict(zip(("Q1", "Q2", "Q3", "Q4"), q[j], strict=True))}))
    return rows


def _motor_rows(flight: LoggedFlight, order: np.ndarray, vehicle: VehicleConfig,
                settings: ArduPilotLogSettings, stamp: Stamp) -> list[Message]:
    """ESC rpm per instance and RCOU PWM, in the autopilot's motor numbering."""
    rows: list[Message] = []
    i = sample_indices(flight.t, settings.esc_rate, phase=0.005)
    rpm = flight.rotor_speeds[i][:, order] / RPM_TO_RAD_S
    for j, t in enumerate(flight.t[i]):
        for instance, value in enumerate(rpm[j]):
            # Each ESC reports a little after the previous one, as on a real bus.
            rows.append(("ESC", {"TimeUS": stamp(t) + 100 * instance, "Instance": instance,
                                 "RPM": float(value), "RawRPM": float(value), "Volt": 16.0,
                                 "Curr": 2.0, "Temp": 3500, "MotTemp": 3500}))
    i = sample_indices(flight.t, settings.rcou_rate, phase=0.007)
    pwm = np.zeros((i.size, RCOU_OUTPUTS), dtype=int)
    pwm[:, :flight.rotor_count] = np.rint(
        pwm_from_rotor_speed(flight.commands[i][:, order], vehicle))
    rows += [("RCOU", {"TimeUS": stamp(t), **{f"C{c + 1}": int(v) for c, v in enumerate(row)}})
             for t, row in zip(flight.t[i], pwm, strict=True)]
    return rows


def _imu_rows(flight: LoggedFlight, settings: ArduPilotLogSettings,
              stamp: Stamp) -> list[Message]:
    """IMU instance 0: the filtered samples (FRD) at the IMU logging rate."""
    if flight.gyro is None or flight.accel is None:
        return []
    gyro = flu_to_frd(lowpass(flight.t, flight.gyro, settings.gyro_filter_hz))
    accel = flu_to_frd(lowpass(flight.t, flight.accel, settings.accel_filter_hz))
    rate = round((flight.t.size - 1) / (flight.t[-1] - flight.t[0]))
    i = sample_indices(flight.t, settings.imu_rate, phase=0.001)
    return [("IMU", {"TimeUS": stamp(t), "I": 0,
                     **dict(zip(("GyrX", "GyrY", "GyrZ"), gyro[j], strict=True)),
                     **dict(zip(("AccX", "AccY", "AccZ"), accel[j], strict=True)),
                     "T": 45.0, "GH": 1, "AH": 1, "GHz": rate, "AHz": rate})
            for t, j in zip(flight.t[i], i, strict=True)]


def _imu_parameters(flight: LoggedFlight, settings: ArduPilotLogSettings) -> dict[str, float]:
    """INS_GYRO_FILTER, INS_ACCEL_FILTER and, where stated, INS_POS1_X/Y/Z (FRD)."""
    if flight.gyro is None:
        return {}
    values = {"INS_GYRO_FILTER": settings.gyro_filter_hz,
              "INS_ACCEL_FILTER": settings.accel_filter_hz}
    if flight.imu_position is not None:
        frd = flu_to_frd(np.asarray(flight.imu_position, dtype=float))
        values.update(zip(("INS_POS1_X", "INS_POS1_Y", "INS_POS1_Z"), frd.tolist(), strict=True))
    return values


def write_ardupilot_log(path: Path, flight: LoggedFlight, vehicle: VehicleConfig,
                        motor_order: Sequence[int],
                        settings: ArduPilotLogSettings | None = None,
                        parameters: Mapping[str, float] | None = None) -> Path:
    """Write ``flight`` as ArduCopter would log it.

    Parameters
    ----------
    path : Path
        The ``.bin`` file to write.
    flight : LoggedFlight
        The flight, in the config's conventions (ENU/FLU, rad/s, config rotor order).
    vehicle : VehicleConfig
        The vehicle flown: its `[motor]` curve turns commands into RCOU PWM.
    motor_order : sequence of int
        Config rotor (0-based) driven by ArduPilot's motor 1, 2, … of the frame.
    settings : ArduPilotLogSettings, optional
    parameters : mapping of str to float, optional
        ``PARM`` values to log (e.g. ``{"FRAME_CLASS": 1, "FRAME_TYPE": 1}``); they
        replace the IMU's own (INS_GYRO_FILTER, INS_POS1_X, …) of the same name.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        ``motor_order`` is not a permutation of the rotors, or more than 14 rotors.
    """
    settings = settings or ArduPilotLogSettings()
    order = check_motor_order(motor_order, flight.rotor_count)
    if flight.rotor_count > RCOU_OUTPUTS:
        raise ValueError(f"{flight.rotor_count} rotors: RCOU logs at most {RCOU_OUTPUTS} outputs")

    stamp = microsecond_stamp(settings.boot_time)

    start = stamp(flight.t[0]) - 1000
    header: list[Message] = [("MSG", {"TimeUS": start, "Message": settings.firmware.encode()})]
    logged = {**_imu_parameters(flight, settings), **(parameters or {})}
    header += [("PARM", {"TimeUS": start, "Name": name.encode(), "Value": float(value),
                         "Default": float(value)})
               for name, value in logged.items()]
    data = (_mode_rows(flight, stamp) + _ekf_rows(flight, settings.ekf_rate, stamp)
            + _motor_rows(flight, order, vehicle, settings, stamp)
            + _imu_rows(flight, settings, stamp))
    # By TimeUS, stable: a log is written in time order.
    data.sort(key=lambda row: row[1]["TimeUS"])
    write_dataflash(path, ARDUPILOT_MESSAGES, header + data)
    return path
