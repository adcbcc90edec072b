"""Autopilot logs (``.tlog``, ``.ulg``, ``.bin``) as `LogStreams` in the project's conventions.

Each format's module reads its log into a `ParsedLog` in the log's own conventions
(`mavsysid.formats.tlog.read_tlog`, `mavsysid.formats.ulog.read_ulog`,
`mavsysid.formats.dataflash.read_dataflash`): NED/FRD and the autopilot's motor numbering.
`read_autopilot_log` makes `LogStreams` of it:

- the pose in ENU/FLU (`mavsysid.vehicle.frames`); the autopilot's separately timed
  position and attitude combined into one pose (`combine_pose`);
- the motor outputs in the config's rotor order (`rotors_in_config_order`): more motor
  outputs than rotors are refused unless the vehicle names its autopilot frame, through
  which (`mavsysid.vehicle.motor_order`) the outputs are put into the config's order.
  Fewer outputs than rotors are left to the checks (`mavsysid.estimation.readers.checks`),
  which refuse them;
- the spans in GUIDED/OFFBOARD mode of the modes the reader found
  (`mavsysid.estimation.readers.window.control_spans`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from mavsysid.estimation.readers.streams import LogStreams, combine_pose
from mavsysid.estimation.readers.window import control_spans
from mavsysid.formats.parsed_log import ParsedLog, Series
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.frames import ned_to_enu, quaternion_ned_to_enu
from mavsysid.vehicle.motor_order import AUTOPILOT_FRAMES, MotorOrderError, output_to_rotor

from mavsysid.errors import ConfigError, LogFormatError

__all__ = ["read_autopilot_log", "rotors_in_config_order"]


def read_autopilot_log(read: Callable[[Path, VehicleConfig], ParsedLog], path: Path,
                       vehicle: VehicleConfig) -> LogStreams:
    """Read an autopilot log with its format's reader, in the project's conventions.

    Parameters
    ----------
    read : callable
        The format's reader, ``(path, vehicle) → ParsedLog``.
    path : Path
        The log.
    vehicle : VehicleConfig
        The vehicle that flew: its motor curve (for the reader), rotors and autopilot frame.

    Returns
    -------
    LogStreams
        Pose in ENU/FLU, rotor speeds in rad/s in the config's rotor order, on the log's
        clock; warnings of reading, combining and ordering, in that order.

    Raises
    ------
    LogFormatError
        What the reader raises, separately timed position and attitude that cannot be
        combined, or more motor outputs than rotors without an autopilot frame.
    """
    log = read(path, vehicle)
    notes = list(log.notes)
    pose = None
    if log.pose is not None:
        p, q = log.pose.values[:, :3], log.pose.values[:, 3:7]
        pose = Series(log.pose.t, np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)]),
                      log.pose.label)
    elif log.position is not None and log.attitude is not None:
        pose, combined = combine_pose(log.source, log.position, log.attitude)
        notes += combined
    rotors, ordered = rotors_in_config_order(log.source, log.rotors, vehicle)
    return LogStreams(source=log.source, pose=pose, pose_source=log.pose_source, rotors=rotors,
                      warnings=(*notes, *log.rotor_notes, *ordered), pose_hint=log.pose_hint,
                      control_spans=None if log.modes is None else control_spans(log.modes))


def _frames_with(count: int) -> str:
    names = [name for name, layout in AUTOPILOT_FRAMES.items() if len(layout) == count]
    return ", ".join(f'"{n}"' for n in names) if names else "a frame of the log's autopilot"


def rotors_in_config_order(source: str, rotors: tuple[Series, ...],
                           vehicle: VehicleConfig) -> tuple[tuple[Series, ...], list[str]]:
    """The log's motor-output series, put into the config's rotor order.

    Parameters
    ----------
    source : str
        The log, for messages.
    rotors : tuple of Series
        Rotor speeds (rad/s) of motor outputs 1..m, their columns concatenated in output
        order, as the reader found them.
    vehicle : VehicleConfig
        The vehicle; its ``autopilot_frame`` (or None: output i is rotor i).

    Returns
    -------
    rotors : tuple of Series
        The same series when no frame is named (or m < k), else columns 1..k in the
        config's rotor order (one series per column when the outputs span several series).
    notes : list of str
        A note when outputs beyond the frame's were left out.

    Raises
    ------
    LogFormatError
        More motor outputs than rotors and no autopilot frame named.
    ConfigError
        A vehicle built in code whose rotors do not match its named frame.
    """
    columns = [(s, c) for s in rotors for c in range(s.values.shape[1])]
    m, k, frame = len(columns), vehicle.rotor_count, vehicle.autopilot_frame
    if m > k and frame is None:
        labels = ", ".join(dict.fromkeys(s.label for s in rotors))
        raise LogFormatError(
            f"{source}: the log has {m} motor outputs ({labels}), vehicle {vehicle.name} has "
            f"{k} rotors; name the autopilot frame in the vehicle file ([autopilot] frame = "
            f"{_frames_with(k)}) or use a vehicle with {m} rotors")
    if frame is None or m < k:
        return rotors, []
    try:
        order = output_to_rotor(vehicle.rotor_positions, vehicle.rotor_directions, frame)
    except MotorOrderError as exc:
        raise ConfigError(f"{vehicle.source or vehicle.name}: [autopilot].frame: {exc}") from None
    notes = ([f"{source}: motor outputs {k + 1}..{m} are not motors of {frame}; left out"]
             if m > k else [])
    inverse = np.argsort(order)  # config rotor j is output inverse[j]
    if len(rotors) == 1:
        only = rotors[0]
        return (Series(only.t, only.values[:, inverse], f"{only.label} ({frame} order)"),), notes
    ordered = []
    for j in inverse:
        series, column = columns[j]
        ordered.append(Series(series.t, series.values[:, [column]],
                              f"{series.label} output {j + 1}"))
    return tuple(ordered), notes
