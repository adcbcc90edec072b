"""The pose of an ArduPilot DataFlash log: the best source present, every generation.

In order of preference:

1. ``VISP`` (vision position: what a motion-capture or vision system sent the vehicle):
   ``TimeUS,RTimeUS,CTimeMS,PX,PY,PZ,Roll,Pitch,Yaw,…`` (m NED, deg Z-Y-X), at CTimeMS
   (the measurement's time on the autopilot clock, corrected for the link), else TimeUS.
   ``pose_source = "motion_capture"``.
2. EKF3 position ``XKF1`` PN, PE, PD with its quaternion ``XKQ`` Q1..Q4.
3. EKF2 position ``NKF1`` with ``NKQ``.
4. An EKF position (``XKF1``, ``NKF1``, or the 3.2-era EKF1 ``TimeMS,…,PN,PE,PD``) with
   ``ATT`` Roll, Pitch, Yaw.
5. ``POS`` Lat, Lng (deg), Alt (m), made local about the first sample, with ``ATT``.

2–5 are the autopilot's estimate (``pose_source = "autopilot"``). ``ATT`` is centi-degrees
(``"IccccCC"``, ``"QccccCCCC"``) in older logs and float degrees (``"QffffffB"``) in 4.x:
the reader's format scaling makes both degrees.

EKF cores (multi-IMU): ArduPilot 4.x tags each row with core index ``C`` (``XKF1``
``"QBccCfffffffccce"``, ``XKQ``/``NKQ`` ``"QBffff" TimeUS,C,Q1..Q4``); 3.5–3.6 logged core 0
as ``XKF1``/``XKQ1`` and core 1 as ``XKF6``/``XKQ2`` (``NKF1``/``NKQ1``, ``NKF6``/``NKQ2``
for EKF2). The primary core is the most frequent ``PI`` (primary index) of ``XKF4``/``NKF4``
when logged and present, else the lowest core: one core throughout keeps the pose
continuous across lane switches.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation.readers.dataflash_messages import (
    Messages,
    field_array,
    has_fields,
    message_times,
)
from mavsysid.estimation.readers.streams import PoseSource, Series, combine_pose
from mavsysid.vehicle.frames import euler_ned_to_quaternion, ned_to_enu, quaternion_ned_to_enu

__all__ = ["POSE_HINT", "POSE_TYPES", "dataflash_pose"]

_EARTH_RADIUS = 6378137.0  # m, WGS-84 equatorial: a local flat-earth map is enough here


@dataclass(frozen=True)
class _Ekf:
    """Where one EKF generation logs its position, quaternion and primary core."""

    position: str  # tagged with C in 4.x, else core 0
    position_cores: dict[str, int]  # 3.5–3.6 per-core names
    attitude: str
    attitude_cores: dict[str, int]
    status: tuple[str, ...]  # messages with the PI (primary index) field


_EKF3 = _Ekf("XKF1", {"XKF1": 0, "XKF6": 1}, "XKQ", {"XKQ1": 0, "XKQ2": 1}, ("XKF4", "XKF9"))
_EKF2 = _Ekf("NKF1", {"NKF1": 0, "NKF6": 1}, "NKQ", {"NKQ1": 0, "NKQ2": 1}, ("NKF4", "NKF9"))
_EKF1 = _Ekf("EKF1", {"EKF1": 0}, "", {}, ())

POSE_TYPES = ("VISP", "POS", "ATT", *(name for ekf in (_EKF3, _EKF2, _EKF1) for name in (
    ekf.position, *ekf.position_cores, ekf.attitude, *ekf.attitude_cores, *ekf.status) if name))
POSE_HINT = ("no VISP, nor XKF1 with XKQ, NKF1 with NKQ, XKF1, NKF1 or EKF1 with ATT, or POS "
             "with ATT")

_PoseResult = tuple[Series | None, PoseSource, list[str]]


def _by_core(found: Messages, tagged: str, split: dict[str, int]) -> dict[int, list[Any]]:
    """Rows by EKF core: from the C field of `tagged`, else from per-core names."""
    cores: dict[int, list[Any]] = defaultdict(list)
    rows = found.get(tagged, [])
    if has_fields(rows, ["C"]):
        for m in rows:
            cores[int(m.C)].append(m)
        return dict(cores)
    for name, core in split.items():
        if found.get(name):
            cores[core] = found[name]
    return dict(cores)


def _primary(found: Messages, ekf: _Ekf, usable: set[int]) -> int:
    """The core flagged primary most often (XKF4/NKF4 PI) if usable, else the lowest."""
    flagged = Counter(int(m.PI) for name in ekf.status for m in found.get(name, [])
                      if "PI" in m.get_fieldnames())
    for core, _ in flagged.most_common():
        if core in usable:
            return core
    return min(usable)


def _degrees_to_quaternion(rows: list[Any]) -> np.ndarray:
    return euler_ned_to_quaternion(*np.radians(field_array(rows, ["Roll", "Pitch", "Yaw"])).T)


def _local_from_global(rows: list[Any]) -> np.ndarray:
    """POS latitude, longitude (deg) and altitude (m) → NED, m, about the first sample."""
    lat, lng, alt = field_array(rows, ["Lat", "Lng", "Alt"]).T
    north = np.radians(lat - lat[0]) * _EARTH_RADIUS
    east = np.radians(lng - lng[0]) * _EARTH_RADIUS * np.cos(np.radians(lat[0]))
    return np.column_stack([north, east, -(alt - alt[0])])


def _vision(found: Messages) -> Series:
    rows = found["VISP"]
    corrected = field_array(rows, ["CTimeMS"])[:, 0] * 1e-3
    t = np.where(corrected > 0.0, corrected, message_times(rows))
    p = field_array(rows, ["PX", "PY", "PZ"])
    q = _degrees_to_quaternion(rows)
    return Series(t, np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)]), "VISP")


def _ekf_position(found: Messages, ekf: _Ekf, need_attitude: bool
                  ) -> tuple[Series, Series | None] | None:
    """The primary core's EKF position and (if logged) quaternion, or None."""
    positions = _by_core(found, ekf.position, ekf.position_cores)
    attitudes = _by_core(found, ekf.attitude, ekf.attitude_cores) if ekf.attitude else {}
    usable = set(positions) & set(attitudes) if need_attitude else set(positions)
    if not usable:
        return None
    core = _primary(found, ekf, usable)
    rows = positions[core]
    label = f"{rows[0].get_type()} core {core}"
    position = Series(message_times(rows), field_array(rows, ["PN", "PE", "PD"]), label)
    if core not in attitudes:
        return position, None
    rows = attitudes[core]
    label = f"{rows[0].get_type()} core {core}"
    return position, Series(message_times(rows), field_array(rows, ["Q1", "Q2", "Q3", "Q4"]),
                            label)


def _att(found: Messages) -> Series:
    rows = found["ATT"]
    return Series(message_times(rows), _degrees_to_quaternion(rows), "ATT")


def dataflash_pose(path: Path, found: Messages) -> _PoseResult:
    """The best pose of a DataFlash log.

    Parameters
    ----------
    path : Path
        The log, for messages.
    found : Messages
        Its messages of `POSE_TYPES`.

    Returns
    -------
    pose : Series or None
        ENU/FLU pose (m = 7), None if no source is present.
    pose_source : {"motion_capture", "autopilot"}
    warnings : list of str
        From cleaning the samples.
    """
    if found.get("VISP"):
        return _vision(found), "motion_capture", []
    for ekf in (_EKF3, _EKF2):
        pair = _ekf_position(found, ekf, need_attitude=True)
        if pair is not None and pair[1] is not None:
            pose, notes = combine_pose(str(path), pair[0], pair[1])
            return pose, "autopilot", notes
    if found.get("ATT"):
        for ekf in (_EKF3, _EKF2, _EKF1):
            pair = _ekf_position(found, ekf, need_attitude=False)
            if pair is not None:
                pose, notes = combine_pose(str(path), pair[0], _att(found))
                return pose, "autopilot", notes
        if found.get("POS"):
            rows = found["POS"]
            position = Series(message_times(rows), _local_from_global(rows), "POS")
            pose, notes = combine_pose(str(path), position, _att(found))
            return pose, "autopilot", notes
    return None, "autopilot", []
