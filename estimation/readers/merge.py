"""Merging an external motion-capture pose (``--pose``) with a flight log's rotor speeds.

The merged flight keeps the flight log's clock and rotor speeds and takes its pose from
the motion-capture file (``pose_source = "motion_capture"``), shifted by the clock
offset: given, or found by `mavsysid.estimation.readers.time_align.estimate_time_offset`. Either
way the offset is reported as an ``info:`` line in the warnings.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mavsysid.estimation.readers.checks import normalise_quaternions, repair_samples
from mavsysid.estimation.readers.streams import LogStreams
from mavsysid.estimation.readers.time_align import estimate_time_offset
from mavsysid.formats.parsed_log import Series
from mavsysid.formats.poselog import read_external_pose

from mavsysid.errors import LogFormatError

__all__ = ["merge_pose"]


def merge_pose(log: LogStreams, pose_path: Path, time_offset: float | None) -> LogStreams:
    """Replace the pose of a flight log by a motion-capture pose on the log's clock.

    Parameters
    ----------
    log : LogStreams
        The flight log as its reader returned it.
    pose_path : Path
        CSV with ``t, x, y, z, qw, qx, qy, qz`` (world ENU, body FLU → world ENU);
        rotor columns may be absent and are ignored.
    time_offset : float or None
        s, with t_log = t_mocap + time_offset; None to find it by cross-correlation.

    Returns
    -------
    LogStreams
        Source ``"LOG + pose POSE"``, the motion-capture pose shifted onto the log's
        clock, the log's rotor speeds, and the warnings of both plus the offset line.
    """
    label = str(pose_path)
    raw = read_external_pose(pose_path)
    t, values, notes = repair_samples(raw.t, raw.values, label, "pose")
    if t.shape[0] < 2:
        raise LogFormatError(f"{label}: fewer than 2 usable pose samples")
    q, more = normalise_quaternions(values[:, 3:7], t, label, "pose")
    notes += more
    mocap = Series(t, np.column_stack([values[:, :3], q]), raw.label)
    if time_offset is None:
        time_offset, how = estimate_time_offset(log, mocap, label)
    else:
        how = "given"
    notes.append(f"info: {label}: motion-capture clock offset {time_offset:+.4f} s onto "
                 f"{log.source} ({how})")
    return LogStreams(source=f"{log.source} + pose {label}",
                      pose=Series(t + time_offset, mocap.values, raw.label),
                      pose_source="motion_capture", rotors=log.rotors,
                      warnings=(*log.warnings, *notes), truth=log.truth)
