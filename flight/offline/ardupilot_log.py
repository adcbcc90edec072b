"""A simulated flight written as ArduCopter writes its DataFlash log (``.bin``).

Messages, their format strings and column names as ArduPilot 4.5 logs them
(``libraries/AP_Logger/LogStructure.h``, ``AP_NavEKF3`` and ``AP_ESC_Telem`` logging):

- ``MSG`` (firmware string) and ``PARM`` (e.g. FRAME_CLASS, FRAME_TYPE) at the start;
- ``MODE`` at each mode change: LOITER for the take-off, GUIDED for the calibration part
  (what ``mavsysid stream`` commands), LAND;
- ``XKF1`` (EKF3 core 0: Roll, Pitch, Yaw in centidegrees, VN, VE, VD, PN, PE, PD, NED)
  and ``XKQ`` (Q1..Q4, NED/FRD) at 25 Hz: Copter writes them from its 25 Hz logging
  loop with LOG_BITMASK's ATTITUDE_FAST (``Copter::twentyfive_hz_logging``);
- ``ESC`` per instance (RPM): ESC telemetry or bidirectional DShot, one message per ESC
  and update;
- ``RCOU`` C1..C14 PWM at 10 Hz (``Copter::ten_hz_logging_loop``).

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
    microsecond_stamp,
    pwm_from_rotor_speed,
    sample_indices,
)
from mavsysid.formats.dataflash_writer import DataFlashFormat, write_dataflash
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import enu_to_ned, quaternion_enu_to_ned
from scipy.spatial.transform import Rotation

Stamp = Callable[[float], int]  # flight time, s → log time, µs since boot

__all__ = ["ARDUPILOT_FORMATS", "ArduPilotLogSettings", "write_ardupilot_log"]

#: The messages written, as (type id, format, columns); ids are the log's own choice.
ARDUPILOT_FORMATS: dict[str, DataFlashFormat] = {
    "PARM": (64, "QNff", "TimeUS,Name,Value,Default"),
    "MSG": (91, "QZ", "TimeUS,Message"),
    "MODE": (11, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "XKF1": (181, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,"
                                      "GX,GY,GZ,OH"),
    "XKQ": (188, "QBffff", "TimeUS,C,Q1,Q2,Q3,Q4"),
    "ESC": (153, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
    "RCOU": (34, "QHHHHHHHHHHHHHH", "TimeUS," + ",".join(f"C{i}" for i in range(1, 15))),
}
_RC_COMMAND, _GCS_COMMAND = 1, 2  # ModeReason
_OUTPUTS = 14


@dataclass(frozen=True)
class ArduPilotLogSettings:
    """Rates and clock of the written log.

    Attributes
    ----------
    ekf_rate, esc_rate, rcou_rate : float
        Hz: XKF1/XKQ (25 with ATTITUDE_FAST), ESC rpm per instance, RCOU (10).
    boot_time : float
        s from the autopilot's boot to the flight's t = 0.
    firmware : str
        The ``MSG`` firmware line.
    """

    ekf_rate: float = 25.0
    esc_rate: float = 50.0
    rcou_rate: float = 10.0
    boot_time: float = 30.0
    firmware: str = "ArduCopter V4.5.7 (mavsysid simulation)"


def _mode_rows(flight: LoggedFlight, stamp: Stamp) -> list[tuple[str, tuple[Any, ...]]]:
    """MODE at take-off (LOITER), calibration start (GUIDED) and end (LAND)."""
    p = flight.phases
    changes = ((p.takeoff, "LOITER", _RC_COMMAND), (p.calibration_start, "GUIDED", _GCS_COMMAND),
               (p.calibration_end, "LAND", _GCS_COMMAND))
    return [("MODE", (stamp(t), ARDUCOPTER_MODES[name], ARDUCOPTER_MODES[name], reason))
            for t, name, reason in changes]


def _ekf_rows(flight: LoggedFlight, rate: float, stamp: Stamp) -> list[tuple[str, tuple]]:
    """XKF1 and XKQ of core 0 at ``rate``."""
    i = sample_indices(flight.t, rate, phase=0.002)
    position, velocity = enu_to_ned(flight.position[i]), enu_to_ned(flight.velocity[i])
    q = quaternion_enu_to_ned(flight.quaternion[i])
    yaw, pitch, roll = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True).T
    rows: list[tuple[str, tuple]] = []
    for j, t in enumerate(flight.t[i]):
        us = stamp(t)
        rows.append(("XKF1", (us, 0, round(roll[j] * 100), round(pitch[j] * 100),
                              round((yaw[j] % 360.0) * 100) % 36000, *velocity[j], 0.0,
                              *position[j], 0, 0, 0, 0)))
        rows.append(("XKQ", (us, 0, *q[j])))
    return rows


def _motor_rows(flight: LoggedFlight, order: np.ndarray, vehicle: VehicleConfig,
                settings: ArduPilotLogSettings, stamp: Stamp) -> list[tuple[str, tuple]]:
    """ESC rpm per instance and RCOU PWM, in the autopilot's motor numbering."""
    rows: list[tuple[str, tuple]] = []
    i = sample_indices(flight.t, settings.esc_rate, phase=0.005)
    rpm = flight.rotor_speeds[i][:, order] / RPM_TO_RAD_S
    for j, t in enumerate(flight.t[i]):
        for instance, value in enumerate(rpm[j]):
            # Each ESC reports a little after the previous one, as on a real bus.
            rows.append(("ESC", (stamp(t) + 100 * instance, instance, float(value),
                                 float(value), 16.0, 2.0, 3500, 0.0, 3500, 0.0)))
    i = sample_indices(flight.t, settings.rcou_rate, phase=0.007)
    pwm = np.zeros((i.size, _OUTPUTS), dtype=int)
    pwm[:, :flight.rotor_count] = np.rint(
        pwm_from_rotor_speed(flight.commands[i][:, order], vehicle))
    rows += [("RCOU", (stamp(t), *map(int, row))) for t, row in zip(flight.t[i], pwm,
                                                                      strict=True)]
    return rows


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
        ``PARM`` values to log (e.g. ``{"FRAME_CLASS": 1, "FRAME_TYPE": 1}``).

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
    if flight.rotor_count > _OUTPUTS:
        raise ValueError(f"{flight.rotor_count} rotors: RCOU logs at most {_OUTPUTS} outputs")

    stamp = microsecond_stamp(settings.boot_time)

    start = stamp(flight.t[0]) - 1000
    header = [("MSG", (start, settings.firmware.encode()))]
    header += [("PARM", (start, name.encode(), float(value), float(value)))
               for name, value in (parameters or {}).items()]
    data = (_mode_rows(flight, stamp) + _ekf_rows(flight, settings.ekf_rate, stamp)
            + _motor_rows(flight, order, vehicle, settings, stamp))
    data.sort(key=lambda row: row[1][0])  # by TimeUS, stable: a log is written in time order
    write_dataflash(path, ARDUPILOT_FORMATS, header + data)
    return path
