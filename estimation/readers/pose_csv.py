"""mavsysid's own flight log ``pose.csv`` as `LogStreams`, with a simulated flight's truth.

The pose log (`mavsysid.formats.poselog`) is already in the project's conventions (world
ENU, body FLU, rad/s in the config's rotor order) and is read strictly by
`mavsysid.formats.poselog.read_pose_log`; a simulated flight's ``meta.json`` next to it
supplies the truth.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from mavsysid.estimation.readers.streams import LogStreams
from mavsysid.formats.flight_dir import STREAM_SOURCE, read_meta
from mavsysid.formats.parsed_log import Series
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["read_pose_csv"]


def read_pose_csv(path: Path, vehicle: VehicleConfig) -> LogStreams:
    """Read a mavsysid pose log, with the truth of a simulated flight.

    Parameters
    ----------
    path : Path
        The ``pose.csv`` file; a ``meta.json`` beside it with ``"simulated": true``
        supplies its ``"truth"`` block, and one written by ``mavsysid stream`` marks the
        pose as the autopilot's estimate.
    vehicle : VehicleConfig
        The vehicle: the file must have its k rotor-speed columns.

    Returns
    -------
    LogStreams
        Pose (motion capture, or the autopilot's estimate for a streamed flight) and rotor
        speeds on the same sample times.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_pose_log(path, vehicle.rotor_count)
    notes = tuple(" ".join(str(w.message).split()) for w in caught)
    truth = None
    pose_source = "motion_capture"
    meta_path = path.parent / "meta.json"
    if meta_path.is_file():
        meta = read_meta(meta_path)
        if meta.get("simulated") is True and isinstance(meta.get("truth"), dict):
            truth = meta["truth"]
        if meta.get("source") == STREAM_SOURCE:
            # `mavsysid stream` records the vehicle's telemetry: its own filtered, lagged
            # estimate of the pose, not a motion-capture measurement.
            pose_source = "autopilot"
    pose = Series(log.t, np.column_stack([log.position, log.quaternion]), "pose")
    rotors = (Series(log.t, log.rotor_speeds, "rotor speed"),)
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source,
                      rotors=rotors, warnings=notes, truth=truth)
