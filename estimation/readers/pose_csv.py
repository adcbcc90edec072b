"""Pose CSV files: mavsysid's own flight log ``pose.csv`` and external motion-capture poses.

Both have the pose-log header (docs/architecture.md) (``t, x, y, z, qw, qx, qy, qz`` in world ENU,
body FLU → world ENU). A flight's ``pose.csv`` also has the rotor speeds ``n1..nk`` and is
read strictly by `mavsysid.formats.poselog.read_pose_log`; a simulated flight's ``meta.json`` next
to it supplies the truth. An external pose file (``--pose``) needs no rotor columns.
"""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import numpy as np
from mavsysid.estimation.readers.streams import LogStreams, Series
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import (
    POSE_COLUMNS,
    parse_plain_rows,
    read_pose_log,
    read_text_file,
)
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import LogFormatError

__all__ = ["read_external_pose", "read_pose_csv"]


def read_pose_csv(path: Path, vehicle: VehicleConfig) -> LogStreams:
    """Read a mavsysid pose log, with the truth of a simulated flight.

    Parameters
    ----------
    path : Path
        The ``pose.csv`` file; a ``meta.json`` beside it with ``"simulated": true``
        supplies its ``"truth"`` block.
    vehicle : VehicleConfig
        The vehicle: the file must have its k rotor-speed columns.

    Returns
    -------
    LogStreams
        Motion-capture pose and rotor speeds on the same sample times.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_pose_log(path, vehicle.rotor_count)
    notes = tuple(" ".join(str(w.message).split()) for w in caught)
    truth = None
    meta_path = path.parent / "meta.json"
    if meta_path.is_file():
        meta = read_meta(meta_path)
        if meta.get("simulated") is True and isinstance(meta.get("truth"), dict):
            truth = meta["truth"]
    pose = Series(log.t, np.column_stack([log.position, log.quaternion]), "pose")
    rotors = (Series(log.t, log.rotor_speeds, "rotor speed"),)
    return LogStreams(source=str(path), pose=pose, pose_source="motion_capture",
                      rotors=rotors, warnings=notes, truth=truth)


def read_external_pose(path: Path) -> Series:
    """Read the pose columns of a motion-capture CSV file (other columns are ignored).

    Parameters
    ----------
    path : Path
        CSV text with a header naming at least ``t, x, y, z, qw, qx, qy, qz``.

    Returns
    -------
    Series
        Times on the motion-capture clock, s, and the pose (m = 7), as in the file (rows
        with NaN or out of order are left for `repair_samples` to report).

    Raises
    ------
    LogFormatError
        A missing column, a short row or a field that is not a number, with its line.
    """
    text = read_text_file(path, "utf-8-sig")
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise LogFormatError(f"{path}: no header row (expected {', '.join(POSE_COLUMNS)})")
    names = [c.strip() for c in next(csv.reader([lines[0]]))]
    missing = [c for c in POSE_COLUMNS if c not in names]
    if missing:
        raise LogFormatError(f"{path}: missing pose column(s) {', '.join(missing)}")
    index = [names.index(c) for c in POSE_COLUMNS]
    rows = [line for line in lines[1:] if line.strip()]
    if not rows:
        raise LogFormatError(f"{path}: no samples, only a header row")
    data = None
    if all(line.count(",") == len(names) - 1 for line in rows):
        data = parse_plain_rows("\n".join(rows), index)
    if data is None:  # not plain numbers, or a bad row: parse field by field
        data = _parse_fields(path, lines, len(names), index)
    return Series(data[:, 0], data[:, 1:], f"pose of {path.name}")


def _parse_fields(path: Path, lines: list[str], ncol: int, index: list[int]) -> np.ndarray:
    """The columns ``index`` of the data rows, by Python's float; raise at a bad row."""
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != ncol:
            raise LogFormatError(f"{path}: line {number} has {len(fields)} fields, the header "
                                 f"has {ncol}")
        try:
            rows.append([float(fields[j]) for j in index])
        except ValueError:
            bad = next(fields[j].strip() for j in index if not _is_float(fields[j]))
            raise LogFormatError(f"{path}: line {number}: {bad[:24]!r} is not a number") from None
    return np.array(rows, dtype=float)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
