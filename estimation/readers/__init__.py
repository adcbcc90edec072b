"""Flight-log readers: `load_flight` turns any supported log into a checked `FlightData`.

Formats, by file extension: ``.csv`` (mavsysid's pose log), ``.tlog`` (MAVLink telemetry),
``.ulg`` (PX4 ULog), ``.bin`` (ArduPilot DataFlash). Each is read by its module in
`mavsysid.formats`; `READERS` gives, per extension, the pose and rotor speeds in the
project's conventions (`mavsysid.estimation.readers.samples.LogStreams`: ENU/FLU, rad/s,
the config's rotor order; `pose_csv`, `autopilot_logs`). Then `window` picks the part of
the log to use, `merge` optionally replaces the pose by an external motion-capture file,
`streams.to_flight_data` resamples the rotor speeds to the pose times and
`checks.validate_flight` checks the result.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import partial
from pathlib import Path

from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.readers.flight_source import choose_flight_log
from mavsysid.estimation.readers.logs import (
    TimeWindow,
    choose_window,
    control_spans,
    merge_pose,
    read_autopilot_log,
    read_pose_csv,
)
from mavsysid.estimation.readers.recorded_vehicle import check_recorded_vehicle
from mavsysid.estimation.readers.samples import LogStreams, to_flight_data
from mavsysid.formats.bounded_parse import check_log_size
from mavsysid.formats.dataflash import read_dataflash, read_dataflash_modes
from mavsysid.formats.parsed_log import ModeChanges
from mavsysid.formats.tlog import read_tlog
from mavsysid.formats.ulog import read_ulog, read_ulog_modes
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import InputError

__all__ = ["READERS", "TimeWindow", "describe_log_kinds", "load_flight"]

#: The reader of each supported file extension (lower case).
READERS: dict[str, Callable[[Path, VehicleConfig], LogStreams]] = {
    ".csv": read_pose_csv,
    ".tlog": partial(read_autopilot_log, read_tlog),
    ".ulg": partial(read_autopilot_log, read_ulog),
    ".bin": partial(read_autopilot_log, read_dataflash),
}


def describe_log_kinds() -> str:
    """The logs `READERS` reads, in words for the help ("pose.csv, .tlog, .ulg or .bin")."""
    names = ["pose.csv" if extension == ".csv" else extension for extension in READERS]
    return ", ".join(names[:-1]) + " or " + names[-1]


def _existing_file(path: str | Path, what: str) -> Path:
    """`path` as a Path if it is a regular file of at most `MAX_LOG_BYTES`, else one line."""
    path = Path(path)
    if not path.is_file():
        found = "a directory" if path.is_dir() else "no such file"
        raise InputError(f"{path}: {what}: expected a file, found {found}")
    check_log_size(path)
    return path


#: Readers of the autopilot's modes, for formats whose reader does not give them (a
#: second pass over the file, made only when the default window needs it).
_MODE_READERS: dict[str, Callable[[Path], ModeChanges | None]] = {
    ".ulg": read_ulog_modes,
    ".bin": read_dataflash_modes,
}


def _windowed(streams: LogStreams, path: Path, start: float | None, end: float | None,
              auto_window: bool) -> tuple[LogStreams, TimeWindow | None]:
    """The window to use (`choose_window`), with its ``info:`` note added to the streams."""
    if not auto_window and start is None and end is None:
        return streams, None

    def spans() -> tuple[tuple[float, float], ...] | None:
        if streams.control_spans is not None or path.suffix.lower() not in _MODE_READERS:
            return streams.control_spans
        modes = _MODE_READERS[path.suffix.lower()](path)
        return None if modes is None else control_spans(modes)

    window = choose_window(path, start, end, spans)
    if window is None:
        return streams, None
    note = f"info: {path}: the window {window.describe()} is used: {window.reason}"
    return dataclasses.replace(streams, warnings=(*streams.warnings, note)), window


def load_flight(path: str | Path, vehicle: VehicleConfig, pose: str | Path | None = None,
                time_offset: float | None = None, start: float | None = None,
                end: float | None = None, auto_window: bool = True) -> FlightData:
    """Read a flight log as pose and rotor speeds in mavsysid's conventions.

    Parameters
    ----------
    path : str or Path
        The flight log: ``.csv``, ``.tlog``, ``.ulg`` or ``.bin`` (case-insensitive); or a
        flight directory, whose log with the most telling rotor speeds is read
        (`mavsysid.estimation.readers.flight_source.choose_flight_log`, said in a note).
    vehicle : VehicleConfig
        The vehicle that flew: rotor count, nominal c_T and mass for the checks, and the
        ``[motor]`` curve for logs with motor outputs but no rotor speeds.
    pose : str or Path, optional
        A motion-capture pose CSV (``t, x, y, z, qw, qx, qy, qz``, world ENU) to use
        instead of the log's own pose; the log then supplies the rotor speeds and clock.
    time_offset : float, optional
        s, with t_log = t_pose + time_offset; found by cross-correlation if omitted.
        Only meaningful with `pose`.
    start, end : float, optional
        The window to use, s on the log's clock (either side may be open); given, it
        replaces the default window.
    auto_window : bool
        Without `start` and `end`, use the default window
        (`mavsysid.estimation.readers.logs.choose_window`: the trajectory flown by
        ``mavsysid stream``, else the longest GUIDED/OFFBOARD span); False: the whole log.

    Returns
    -------
    FlightData
        Times on the log's clock (the autopilot's, s since boot, for autopilot logs),
        position in m (world ENU), unit quaternions [w, x, y, z] (body FLU → world ENU),
        rotor speeds in rad/s resampled to the pose times, and warnings of repairs.

    Raises
    ------
    InputError
        An unsupported extension or a missing file; a flight whose ``meta.json`` says it
        was flown as another vehicle (`check_recorded_vehicle`).
    LogFormatError
        A log that cannot be read or fails a check (`mavsysid.estimation.readers.samples`); the
        message is one line naming the file.
    """
    chosen = None
    if Path(path).is_dir():
        path, streams, chosen = choose_flight_log(Path(path), vehicle, READERS)
    path = _existing_file(path, "flight log")
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        known = ", ".join(READERS)
        raise InputError(f"{path}: unsupported flight log type {path.suffix or '(none)'!r}; "
                         f"expected one of {known}")
    if pose is None and time_offset is not None:
        raise InputError(f"{path}: a time offset applies only with a motion-capture pose file")
    edited = check_recorded_vehicle(path, vehicle)
    if chosen is None:
        streams = reader(path, vehicle)
    else:
        streams = dataclasses.replace(streams, warnings=(chosen, *streams.warnings))
    streams, window = _windowed(streams, path, start, end, auto_window)
    if pose is not None:
        streams = merge_pose(streams, _existing_file(pose, "motion-capture pose"), time_offset)
    flight = to_flight_data(streams, vehicle, None if window is None else window.bounds)
    if edited is None:
        return flight
    return dataclasses.replace(flight, warnings=(*flight.warnings, edited))
