"""A simulated flight written as PX4 writes its ULog (``.ulg``).

What PX4 1.14/1.15's logger writes of the flight and when (``src/modules/logger/
logged_topics.cpp``), with the high-rate profile (SDLOG_PROFILE) a system-identification
flight uses; the topics themselves (fields, units, frames) are `mavsysid.formats.ulog`'s
`PX4_TOPICS`:

- ``vehicle_status`` (``nav_state``: POSCTL for the take-off, OFFBOARD for the
  calibration part, what ``mavsysid stream`` commands, AUTO_LAND), at 2 Hz and on change;
- ``vehicle_local_position`` (x, y, z, vx, vy, vz, NED) at 10 Hz (the default 100 ms
  interval) and ``vehicle_attitude`` (q, NED/FRD) at the high-rate profile's full rate;
- ``vehicle_mocap_odometry`` (position, q) at 30 Hz when the flight had motion capture;
- ``esc_status`` (``esc[i].esc_rpm``) and ``actuator_motors`` (relative thrust
  ``control[i]``, NaN for unused motors), both high-rate topics;
- ``sensor_combined`` (``gyro_rad``, ``accelerometer_m_s2``, body FRD) at IMU_INTEG_RATE
  (250 Hz by default, logged at full rate): the IMU's samples, which PX4 averages over
  each integration interval without a low-pass, with the parameters IMU_INTEG_RATE and,
  when the flight states the IMU's position, EKF2_IMU_POS_X/Y/Z (m, body FRD).

ESC i and motor control i are PX4's motor i + 1, mapped to the config's rotors by
``motor_order``. Timestamps are µs since boot; the flight starts ``boot_time`` after boot.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mavsysid.flight.offline.autopilot_log import (
    LoggedFlight,
    check_motor_order,
    microsecond_stamp,
    sample_indices,
)
from mavsysid.formats.motor_curve import throttle_from_rotor_speed
from mavsysid.formats.ulog import (
    ARMING_STATE_ARMED,
    ESC_SLOTS,
    MOTOR_SLOTS,
    NAVIGATION_STATES,
    PX4_TOPICS,
    Row,
    write_ulog,
)
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import enu_to_ned, flu_to_frd, quaternion_enu_to_ned

Stamp = Callable[[float], int]  # flight time, s → log time, µs since boot

__all__ = ["PX4LogSettings", "write_px4_log"]


@dataclass(frozen=True)
class PX4LogSettings:
    """Rates, pose source and clock of the written log.

    Attributes
    ----------
    local_position_rate, attitude_rate, mocap_rate, esc_rate, motors_rate : float
        Hz of each topic (at most the flight's own rate is met).
    imu_rate : float
        Hz of sensor_combined (IMU_INTEG_RATE).
    motion_capture : bool
        Write ``vehicle_mocap_odometry`` (motion capture forwarded to PX4).
    boot_time : float
        s from boot to the flight's t = 0.
    """

    local_position_rate: float = 10.0
    attitude_rate: float = 100.0
    mocap_rate: float = 30.0
    esc_rate: float = 100.0
    motors_rate: float = 100.0
    imu_rate: float = 250.0
    motion_capture: bool = False
    boot_time: float = 30.0


#: The simulated vehicle's PX4 mode names → vehicle_status nav_state names.
_NAV_STATE_OF_MODE = {"HOLD": "AUTO_LOITER", "LAND": "AUTO_LAND", "TAKEOFF": "AUTO_TAKEOFF"}


def _status_rows(flight: LoggedFlight, stamp: Stamp) -> list[Row]:
    """vehicle_status at 2 Hz and at each mode change, from take-off to landed."""
    changes = [(t, _NAV_STATE_OF_MODE.get(name, name))
               for t, name in flight.modes(("POSCTL", "OFFBOARD", "AUTO_LAND"))]
    changes = [(t, name) for t, name in changes if name in NAVIGATION_STATES]
    if not changes:
        return []
    times = np.union1d(np.arange(flight.t[0], flight.t[-1], 0.5), [t for t, _ in changes])
    rows = []
    for t in times:
        since, name = max((c for c in changes if c[0] <= t), default=changes[0])
        rows.append({"timestamp": stamp(t), "nav_state_timestamp": stamp(since),
                     "nav_state": NAVIGATION_STATES[name], "arming_state": ARMING_STATE_ARMED})
    return rows


def _pose_topics(flight: LoggedFlight, s: PX4LogSettings, stamp: Stamp) -> dict[str, list[Row]]:
    """vehicle_local_position, vehicle_attitude and, with motion capture, odometry."""
    topics: dict[str, list[Row]] = {}
    i = sample_indices(flight.t, s.local_position_rate, phase=0.003)
    p, v = enu_to_ned(flight.position[i]), enu_to_ned(flight.velocity[i])
    topics["vehicle_local_position"] = [
        {"timestamp": stamp(t) + 200, "timestamp_sample": stamp(t), "xy_valid": 1,
         "z_valid": 1, **dict(zip(("x", "y", "z", "vx", "vy", "vz"), (*p[j], *v[j]),
                                  strict=True))}
        for j, t in enumerate(flight.t[i])]
    i = sample_indices(flight.t, s.attitude_rate, phase=0.0)
    q = quaternion_enu_to_ned(flight.quaternion[i])
    topics["vehicle_attitude"] = [
        {"timestamp": stamp(t) + 150, "timestamp_sample": stamp(t),
         **{f"q[{c}]": q[j, c] for c in range(4)}} for j, t in enumerate(flight.t[i])]
    if s.motion_capture:
        i = sample_indices(flight.t, s.mocap_rate, phase=0.004)
        p, q = enu_to_ned(flight.position[i]), quaternion_enu_to_ned(flight.quaternion[i])
        topics["vehicle_mocap_odometry"] = [
            {"timestamp": stamp(t) + 3000, "timestamp_sample": stamp(t), "pose_frame": 1,
             **{f"position[{c}]": p[j, c] for c in range(3)},
             **{f"q[{c}]": q[j, c] for c in range(4)}} for j, t in enumerate(flight.t[i])]
    return topics


def _motor_topics(flight: LoggedFlight, order: np.ndarray, rotor_speed_max: float,
                  s: PX4LogSettings, stamp: Stamp) -> dict[str, list[Row]]:
    """esc_status rpm and actuator_motors relative thrust, in PX4's motor numbering."""
    k = flight.rotor_count
    i = sample_indices(flight.t, s.esc_rate, phase=0.006)
    rpm = np.rint(flight.rotor_speeds[i][:, order] / RPM_TO_RAD_S).astype(int)
    esc = [{"timestamp": stamp(t), "counter": j % 65536, "esc_count": k,
            "esc_connectiontype": 6,  # DShot
            **{f"esc[{m}].esc_rpm": int(rpm[j, m]) for m in range(k)},
            **{f"esc[{m}].timestamp": stamp(t) for m in range(k)},
            **{f"esc[{m}].esc_voltage": 16.0 for m in range(k)}}
           for j, t in enumerate(flight.t[i])]
    i = sample_indices(flight.t, s.motors_rate, phase=0.001)
    # control is relative thrust: thrust ∝ n² (PX4 applies THR_MDL_FAC after it).
    thrust = throttle_from_rotor_speed(flight.commands[i][:, order], rotor_speed_max, 0.0)
    motors = [{"timestamp": stamp(t), "timestamp_sample": stamp(t),
               **{f"control[{m}]": float(thrust[j, m]) if m < k else np.nan
                  for m in range(MOTOR_SLOTS)}}
              for j, t in enumerate(flight.t[i])]
    return {"esc_status": esc, "actuator_motors": motors}


def _imu_topics(flight: LoggedFlight, s: PX4LogSettings, stamp: Stamp
                ) -> tuple[dict[str, list[Row]], dict[str, float | int]]:
    """sensor_combined at the IMU rate (FRD), and the parameters that describe it."""
    if flight.gyro is None or flight.accel is None:
        return {}, {}
    i = sample_indices(flight.t, s.imu_rate, phase=0.0005)
    gyro, accel = flu_to_frd(flight.gyro[i]), flu_to_frd(flight.accel[i])
    dt = round(1e6 / s.imu_rate)
    rows = [{"timestamp": stamp(t), "gyro_integral_dt": dt, "accelerometer_integral_dt": dt,
             **{f"gyro_rad[{c}]": gyro[j, c] for c in range(3)},
             **{f"accelerometer_m_s2[{c}]": accel[j, c] for c in range(3)}}
            for j, t in enumerate(flight.t[i])]
    parameters: dict[str, float | int] = {"IMU_INTEG_RATE": round(s.imu_rate)}
    if flight.imu_position is not None:
        frd = flu_to_frd(np.asarray(flight.imu_position, dtype=float)).tolist()
        parameters.update(zip(("EKF2_IMU_POS_X", "EKF2_IMU_POS_Y", "EKF2_IMU_POS_Z"), frd,
                              strict=True))
    return {"sensor_combined": rows}, parameters


def write_px4_log(path: Path, flight: LoggedFlight, rotor_speed_max: float,
                  motor_order: Sequence[int], settings: PX4LogSettings | None = None) -> Path:
    """Write ``flight`` as PX4 would log it.

    Parameters
    ----------
    path : Path
        The ``.ulg`` file to write.
    flight : LoggedFlight
        The flight, in the config's conventions (ENU/FLU, rad/s, config rotor order).
    rotor_speed_max : float
        rad/s at full thrust: ``actuator_motors`` control = (n_cmd / n_max)².
    motor_order : sequence of int
        Config rotor (0-based) driven by PX4's motor 1, 2, … of the airframe.
    settings : PX4LogSettings, optional

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        ``motor_order`` is not a permutation of the rotors, or more than 8 rotors.
    """
    settings = settings or PX4LogSettings()
    order = check_motor_order(motor_order, flight.rotor_count)
    if flight.rotor_count > ESC_SLOTS:
        raise ValueError(f"{flight.rotor_count} rotors: esc_status holds at most {ESC_SLOTS}")

    stamp = microsecond_stamp(settings.boot_time)

    imu, parameters = _imu_topics(flight, settings, stamp)
    topics = {"vehicle_status": _status_rows(flight, stamp),
              **_pose_topics(flight, settings, stamp),
              **_motor_topics(flight, order, rotor_speed_max, settings, stamp), **imu}
    formats = {name: fields for name, fields in PX4_TOPICS.items()
               if name in topics or name == "esc_report"}
    write_ulog(path, formats, topics, info={"sys_name": "PX4", "ver_sw": "v1.15.0",
                                            "sys_mcu": "mavsysid simulation"},
               start_us=round(settings.boot_time * 1e6), parameters=parameters)
    return path
