"""MAVLink telemetry logs (``.tlog``): each message preceded by its receipt time.

Pose: ATT_POS_MOCAP (motion capture forwarded to the vehicle; NED, q [w, x, y, z] FRD →
NED) if present, else LOCAL_POSITION_NED with ATTITUDE_QUATERNION (or ATTITUDE Euler
angles), the autopilot's own estimate. Rotor speeds: ESC_TELEMETRY_1_TO_4 / _5_TO_8 /
_9_TO_12 ``rpm`` (ESC i is motor output i), else the SERVO_OUTPUT_RAW channels that move
(the motors) through the motor curve (a warning says so); the outputs are put into the
config's rotor order by `mavsysid.estimation.readers.motor_outputs`.

Time base: the autopilot's clock (s since boot), because the pose messages carry it
(``time_boot_ms``). ESC_TELEMETRY and ATT_POS_MOCAP carry no autopilot time (the mocap
``time_usec`` is the sender's clock), so they are stamped with the tlog's receipt time
mapped onto the autopilot clock: receipt − time_boot_ms over all autopilot messages
with a ``time_boot_ms`` is the clock offset plus that message's link latency, and its
minimum (the fastest message) is taken as the offset. Stamps mapped so are late by their
own latency minus the smallest one, typically a few ms on a direct link; clock drift
(tens of ppm) is ignored. SERVO_OUTPUT_RAW carries the autopilot's ``time_usec``, used
as is (and in the offset estimate). Without any autopilot time the receipt times are
used, from the first message.

Only messages from the autopilot (the sender of the first HEARTBEAT from an autopilot)
count as the vehicle's, except ATT_POS_MOCAP, which a ground station or companion sends.
The autopilot's HEARTBEATs also give the spans flown in GUIDED/OFFBOARD mode
(``LogStreams.control_spans``, for the default window).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from mavsysid.estimation.readers.guard import import_parser, parsing
from mavsysid.estimation.readers.motor_curve import describe_curve, rotor_speed_from_pwm
from mavsysid.estimation.readers.motor_outputs import motor_output_count, rotors_in_config_order
from mavsysid.estimation.readers.streams import LogStreams, PoseSource, Series, combine_pose
from mavsysid.estimation.readers.window import CONTROLLED_MODES, spans_of
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import (
    euler_ned_to_quaternion,
    ned_to_enu,
    quaternion_ned_to_enu,
)

from mavsysid.errors import LogFormatError

__all__ = ["read_tlog"]

_ESC = {"ESC_TELEMETRY_1_TO_4": 0, "ESC_TELEMETRY_5_TO_8": 4, "ESC_TELEMETRY_9_TO_12": 8}
_CLOCKED = ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "ATTITUDE", "SYSTEM_TIME",
            "GLOBAL_POSITION_INT")
_TYPES = ["HEARTBEAT", "ATT_POS_MOCAP", "SERVO_OUTPUT_RAW", *_CLOCKED, *_ESC]
_POSE_HINT = "no ATT_POS_MOCAP, nor LOCAL_POSITION_NED with ATTITUDE_QUATERNION or ATTITUDE"

# (receipt time s, (system, component), message) per message type.
_Messages = dict[str, list[tuple[float, tuple[int, int], Any]]]


def _collect(path: Path) -> _Messages:
    """All messages of the types used here, by type."""
    mavutil = import_parser("pymavlink.mavutil", path)
    found: _Messages = defaultdict(list)
    with parsing(path, "a MAVLink telemetry log"):
        log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
        try:
            while (m := log.recv_match(type=_TYPES)) is not None:
                if m.get_type() in _TYPES:
                    found[m.get_type()].append(
                        (float(m._timestamp), (m.get_srcSystem(), m.get_srcComponent()), m))
        finally:
            log.close()
    if not found:
        raise LogFormatError(f"{path}: no MAVLink messages with pose, rotor speeds or motor "
                             "outputs (is it a telemetry log?)")
    return found


def _from_autopilot(found: _Messages, mavlink: ModuleType) -> _Messages:
    """The messages sent by the autopilot (all of them if no autopilot HEARTBEAT).

    ``mavlink`` is pymavlink's dialect module, for the MAVLink enums: a ground station's
    HEARTBEAT says type GCS or autopilot INVALID.
    """
    beats = [src for _, src, m in found.get("HEARTBEAT", [])
             if m.autopilot != mavlink.MAV_AUTOPILOT_INVALID and m.type != mavlink.MAV_TYPE_GCS]
    if not beats:
        return found
    return {name: [row for row in rows if row[1] == beats[0]] for name, rows in found.items()}


def _clock_offset(own: _Messages) -> float | None:
    """Receipt time minus autopilot time, s (see the module docstring), or None."""
    lags = [receipt - m.time_boot_ms * 1e-3
            for name in _CLOCKED for receipt, _, m in own.get(name, [])]
    # SERVO_OUTPUT_RAW's time_usec is the same clock (it wraps, but that only raises lags).
    lags += [receipt - m.time_usec * 1e-6 for receipt, _, m in own.get("SERVO_OUTPUT_RAW", [])]
    return min(lags) if lags else None


def _unwrap_us(ticks: np.ndarray) -> np.ndarray:
    """A uint32 microsecond counter (wraps every 71.6 min) made monotonic, in s."""
    steps = np.diff(ticks, prepend=ticks[:1])
    wraps = np.cumsum(steps < -(2.0**31))
    return (ticks + wraps * 2.0**32) * 1e-6


def _pose(path: Path, found: _Messages, own: _Messages,
          offset: float) -> tuple[Series | None, PoseSource, list[str]]:
    """The pose series, its origin and warnings from cleaning it."""
    mocap = found.get("ATT_POS_MOCAP", [])
    if mocap:
        t = np.array([r for r, _, _ in mocap]) - offset
        p = np.array([[m.x, m.y, m.z] for _, _, m in mocap], dtype=float)
        q = np.array([list(m.q) for _, _, m in mocap], dtype=float)
        values = np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)])
        return Series(t, values, "ATT_POS_MOCAP"), "motion_capture", []
    local = own.get("LOCAL_POSITION_NED", [])
    if not local:
        return None, "autopilot", []
    position = Series(np.array([m.time_boot_ms * 1e-3 for _, _, m in local]),
                      np.array([[m.x, m.y, m.z] for _, _, m in local], dtype=float),
                      "LOCAL_POSITION_NED")
    if own.get("ATTITUDE_QUATERNION"):
        rows = own["ATTITUDE_QUATERNION"]
        q = np.array([[m.q1, m.q2, m.q3, m.q4] for _, _, m in rows], dtype=float)
        label = "ATTITUDE_QUATERNION"
    elif own.get("ATTITUDE"):
        rows = own["ATTITUDE"]
        q = euler_ned_to_quaternion(*np.array([[m.roll, m.pitch, m.yaw] for _, _, m in rows],
                                              dtype=float).T)
        label = "ATTITUDE"
    else:
        return None, "autopilot", []
    attitude = Series(np.array([m.time_boot_ms * 1e-3 for _, _, m in rows]), q, label)
    pose, notes = combine_pose(str(path), position, attitude)
    return pose, "autopilot", notes


def _esc_rotors(path: Path, own: _Messages, offset: float,
                k: int) -> tuple[Series, ...]:
    """Rotor speeds from ESC_TELEMETRY_*: as many rotors as ESCs that ever turned."""
    present = {name: own[name] for name in _ESC if own.get(name)}
    turned = [base + j for name, base in _ESC.items() if name in present
              for j in range(4) if any(m.rpm[j] for _, _, m in present[name])]
    # An ESC never turning is a rotor of this vehicle only if the config says so.
    count = max(turned) + 1 if turned else k
    series = []
    for name, base in _ESC.items():
        if base >= count:
            break
        rows = present.get(name)
        if not rows:
            raise LogFormatError(f"{path}: ESC rpm for rotors {base + 1}..{base + 4} missing "
                                 f"(no {name}) while rotors up to {count} report theirs")
        width = min(4, count - base)
        t = np.array([r for r, _, _ in rows]) - offset
        rpm = np.array([list(m.rpm)[:width] for _, _, m in rows], dtype=float)
        series.append(Series(t, rpm * RPM_TO_RAD_S, f"{name} rpm"))
    return tuple(series)


def _servo_rotors(own: _Messages, vehicle: VehicleConfig) -> Series | None:
    """Rotor speeds from SERVO_OUTPUT_RAW port 0, channels 1..k, via the motor curve."""
    rows = [m for _, _, m in own.get("SERVO_OUTPUT_RAW", []) if m.port == 0]
    if not rows:
        return None
    pwm = np.array([[getattr(m, f"servo{i}_raw", 0) or 0 for i in range(1, 17)] for m in rows],
                   dtype=float)
    count = motor_output_count(pwm)
    if count == 0:
        return None
    t = _unwrap_us(np.array([m.time_usec for m in rows], dtype=float))
    return Series(t, rotor_speed_from_pwm(pwm[:, :count], vehicle), "SERVO_OUTPUT_RAW PWM")


def _control_spans(own: _Messages, mavutil: ModuleType,
                   offset: float) -> tuple[tuple[float, float], ...] | None:
    """Spans of the autopilot's HEARTBEATs in GUIDED/OFFBOARD mode, s; None without any."""
    beats = own.get("HEARTBEAT", [])
    if not beats:
        return None
    t = np.array([r for r, _, _ in beats]) - offset
    active = np.array([mavutil.mode_string_v10(m) in CONTROLLED_MODES for _, _, m in beats])
    return tuple(spans_of(t, active, False, float(t[-1])))


def read_tlog(path: Path, vehicle: VehicleConfig) -> LogStreams:
    """Read the pose and rotor speeds of a telemetry log.

    Parameters
    ----------
    path : Path
        The ``.tlog`` file.
    vehicle : VehicleConfig
        The vehicle: its rotor count and motor curve (for SERVO_OUTPUT_RAW).

    Returns
    -------
    LogStreams
        In ENU/FLU and rad/s, on the autopilot's clock (see the module docstring).

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    found = _collect(path)
    mavutil = import_parser("pymavlink.mavutil", path)
    own = _from_autopilot(found, mavutil.mavlink)
    notes: list[str] = []
    offset = _clock_offset(own)
    if offset is None:
        offset = min(rows[0][0] for rows in found.values())
        notes.append(f"{path}: no autopilot time_boot_ms in the log; times are its receipt "
                     "times from the first message")
    with parsing(path, "a MAVLink telemetry log with the usual message fields"):
        pose, pose_source, more = _pose(path, found, own, offset)
        notes += more
        if any(own.get(name) for name in _ESC):
            rotors = _esc_rotors(path, own, offset, vehicle.rotor_count)
        elif (servo := _servo_rotors(own, vehicle)) is not None:
            rotors = (servo,)
            notes.append(f"{path}: no ESC rpm; rotor speeds are motor outputs "
                         "(SERVO_OUTPUT_RAW) through the motor curve "
                         f"{describe_curve(vehicle, pwm=True)}: commanded, not measured, and "
                         "only as right as the [motor] keys of the vehicle config")
        else:
            raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no "
                                 "ESC_TELEMETRY_* rpm, no SERVO_OUTPUT_RAW)")
        spans = _control_spans(own, mavutil, offset)
    rotors, ordered = rotors_in_config_order(str(path), rotors, vehicle)
    notes += ordered
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source,
                      rotors=rotors, warnings=tuple(notes), pose_hint=_POSE_HINT,
                      control_spans=spans)
