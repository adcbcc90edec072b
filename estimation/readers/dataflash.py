"""ArduPilot DataFlash logs (``.bin``), read with pymavlink's DFReader.

Pose, first found of:

- ``VISP`` (vision position: what a motion-capture or vision system sent to the vehicle,
  as ArduPilot logs it): PX, PY, PZ (m, NED) and Roll, Pitch, Yaw (deg, Z-Y-X), at
  CTimeMS (the measurement's time on the autopilot clock, corrected for the link), else
  TimeUS. ``pose_source = "motion_capture"``.
- ``XKF1`` PN, PE, PD with ``XKQ`` Q1..Q4 (EKF3; the lowest core index C logged), else
  ``NKF1``/``NKQ`` (EKF2), else ``POS`` (latitude, longitude, altitude, made local
  about the first sample) with ``ATT`` Roll, Pitch, Yaw: the autopilot's estimate.

Rotor speeds: ``ESC`` RPM by Instance, else ``RCOU`` C1..Ck PWM through the vehicle's
`[motor]` curve (with a warning). ESC instance i and output channel i + 1 are taken as
rotor i + 1 of the vehicle config, one to one. A real ArduPilot frame numbers its motors
its own way (FRAME_CLASS/FRAME_TYPE motor order, SERVOn_FUNCTION): mapping that onto the
config's rotor order is out of scope, so the config must list the rotors in the order of
the autopilot's outputs. Times are TimeUS (µs since boot) → s.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation.readers.guard import import_parser, parsing
from mavsysid.estimation.readers.motor_curve import describe_curve, rotor_speed_from_pwm
from mavsysid.estimation.readers.streams import LogStreams, PoseSource, Series, combine_pose
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import (
    euler_ned_to_quaternion,
    ned_to_enu,
    quaternion_ned_to_enu,
)

from mavsysid.errors import LogFormatError

__all__ = ["read_dataflash"]

_EARTH_RADIUS = 6378137.0  # m, WGS-84 equatorial: a local flat-earth map is enough here
_EKFS = (("XKF1", "XKQ"), ("NKF1", "NKQ"))
_TYPES = ["VISP", "XKF1", "XKQ", "NKF1", "NKQ", "POS", "ATT", "ESC", "RCOU"]
_POSE_HINT = "no VISP, nor XKF1 with XKQ, NKF1 with NKQ or POS with ATT"

_Messages = dict[str, list[Any]]


def _collect(path: Path) -> _Messages:
    """The messages of the types used here, by type."""
    DFReader = import_parser("pymavlink.DFReader", path)
    found: _Messages = defaultdict(list)
    with parsing(path, "an ArduPilot DataFlash log"):
        log = DFReader.DFReader_binary(str(path))
        try:
            while (m := log.recv_match(type=_TYPES)) is not None:
                found[m.get_type()].append(m)
        finally:
            log.close()
    return found


def _array(rows: list[Any], names: list[str]) -> np.ndarray:
    return np.array([[getattr(m, n) for n in names] for m in rows], dtype=float)


def _time_us(rows: list[Any]) -> np.ndarray:
    return _array(rows, ["TimeUS"])[:, 0] * 1e-6


def _degrees_to_quaternion(rows: list[Any]) -> np.ndarray:
    return euler_ned_to_quaternion(*np.radians(_array(rows, ["Roll", "Pitch", "Yaw"])).T)


def _local_from_global(rows: list[Any]) -> np.ndarray:
    """POS latitude, longitude (deg) and altitude (m) → NED, m, about the first sample."""
    lat, lng, alt = _array(rows, ["Lat", "Lng", "Alt"]).T
    north = np.radians(lat - lat[0]) * _EARTH_RADIUS
    east = np.radians(lng - lng[0]) * _EARTH_RADIUS * np.cos(np.radians(lat[0]))
    return np.column_stack([north, east, -(alt - alt[0])])


def _pose(path: Path, found: _Messages) -> tuple[Series | None, PoseSource, list[str]]:
    """The pose series, its origin and warnings from cleaning it."""
    if found.get("VISP"):
        rows = found["VISP"]
        corrected = _array(rows, ["CTimeMS"])[:, 0] * 1e-3
        t = np.where(corrected > 0.0, corrected, _time_us(rows))
        p = _array(rows, ["PX", "PY", "PZ"])
        q = _degrees_to_quaternion(rows)
        values = np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)])
        return Series(t, values, "VISP"), "motion_capture", []
    for kf, kq in _EKFS:
        if found.get(kf) and found.get(kq):
            core = min(int(m.C) for m in found[kf])
            rows_p = [m for m in found[kf] if int(m.C) == core]
            rows_q = [m for m in found[kq] if int(m.C) == core]
            if not rows_q:
                continue
            position = Series(_time_us(rows_p), _array(rows_p, ["PN", "PE", "PD"]), kf)
            attitude = Series(_time_us(rows_q), _array(rows_q, ["Q1", "Q2", "Q3", "Q4"]), kq)
            pose, notes = combine_pose(str(path), position, attitude)
            return pose, "autopilot", notes
    if found.get("POS") and found.get("ATT"):
        position = Series(_time_us(found["POS"]), _local_from_global(found["POS"]), "POS")
        attitude = Series(_time_us(found["ATT"]), _degrees_to_quaternion(found["ATT"]), "ATT")
        pose, notes = combine_pose(str(path), position, attitude)
        return pose, "autopilot", notes
    return None, "autopilot", []


def _esc_rotors(path: Path, rows: list[Any]) -> tuple[Series, ...]:
    """One series per ESC instance 0..m−1, rpm → rad/s."""
    by_instance: dict[int, list[Any]] = defaultdict(list)
    for m in rows:
        by_instance[int(m.Instance)].append(m)
    count = max(by_instance) + 1
    missing = [i + 1 for i in range(count) if i not in by_instance]
    if missing:
        raise LogFormatError(f"{path}: ESC rpm of rotor(s) {', '.join(map(str, missing))} "
                             f"missing while rotors up to {count} report theirs")
    return tuple(Series(_time_us(by_instance[i]), _array(by_instance[i], ["RPM"]) * RPM_TO_RAD_S,
                        f"ESC {i} rpm") for i in range(count))


def _rcou_rotors(rows: list[Any], vehicle: VehicleConfig) -> Series | None:
    """RCOU C1..Ck PWM through the motor curve; None if no channel ever outputs."""
    channels = [c for c in (f"C{i}" for i in range(1, 17)) if c in rows[0].get_fieldnames()]
    pwm = _array(rows, channels)
    used = pwm.any(axis=0)
    # Leading channels that ever output: the motors (later ones may drive other servos).
    count = min(int(np.argmin(used)) if not used.all() else len(channels), vehicle.rotor_count)
    if count == 0:
        return None
    return Series(_time_us(rows), rotor_speed_from_pwm(pwm[:, :count], vehicle), "RCOU PWM")


def read_dataflash(path: Path, vehicle: VehicleConfig) -> LogStreams:
    """Read the pose and rotor speeds of an ArduPilot DataFlash log.

    Parameters
    ----------
    path : Path
        The ``.bin`` file.
    vehicle : VehicleConfig
        The vehicle: its rotor count and motor curve (for RCOU outputs).

    Returns
    -------
    LogStreams
        In ENU/FLU and rad/s, on the autopilot's clock (s since boot).

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    found = _collect(path)
    with parsing(path, "an ArduPilot DataFlash log with the usual message fields"):
        pose, pose_source, notes = _pose(path, found)
        rcou = _rcou_rotors(found["RCOU"], vehicle) if found.get("RCOU") else None
        if found.get("ESC"):
            rotors = _esc_rotors(path, found["ESC"])
        elif rcou is not None:
            rotors = (rcou,)
            notes.append(f"{path}: no ESC rpm; rotor speeds are RCOU motor outputs through the "
                         f"motor curve {describe_curve(vehicle, pwm=True)}: commanded, not "
                         "measured, and only as right as the [motor] keys of the vehicle config")
        else:
            raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no ESC "
                                 "RPM, no RCOU)")
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source, rotors=rotors,
                      warnings=tuple(notes), pose_hint=_POSE_HINT)
