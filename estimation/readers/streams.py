"""What is read from a log, in the project's conventions, and its assembly into a `FlightData`.

Each reader (`mavsysid.estimation.readers.READERS`) returns `LogStreams`: the pose samples
(in ENU/FLU) and one or more rotor-speed series (in rad/s, the config's rotor order), each
on its own clock samples (`mavsysid.formats.parsed_log.Series`). `to_flight_data`
resamples the rotor speeds to the pose times (linear interpolation; pose samples outside
the rotor-speed time span are dropped) and runs the checks of
`mavsysid.estimation.readers.checks`. Keeping the streams apart until then lets `--pose`
swap in a motion-capture pose first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.input_noise import InputSamples
from mavsysid.estimation.readers.checks import (
    check_sampling,
    long_gaps,
    normalise_quaternions,
    repair_samples,
    validate_flight,
)
from mavsysid.formats.parsed_log import PoseSource, Series
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.frames import ned_to_enu, quaternion_ned_to_enu
from mavsysid.vehicle.rotation import interpolate_quaternions

from mavsysid.errors import LogFormatError

__all__ = ["LogStreams", "combine_pose", "to_flight_data"]


@dataclass(frozen=True)
class LogStreams:
    """The pose and rotor speeds found in one log.

    Attributes
    ----------
    source : str
        The file (with ``+ pose FILE`` once merged).
    pose : Series or None
        The pose (m = 7), or None if the log has none.
    pose_source : {"motion_capture", "autopilot"}
        Origin of the pose.
    rotors : tuple of Series
        Rotor speeds, rad/s; their columns, concatenated in order, are rotors 1..k.
    warnings : tuple of str
        Notes from reading, one line each.
    truth : dict or None
        The truth block of a simulated flight.
    pose_hint : str
        What pose messages the reader looked for, for the error when there is none.
    control_spans : tuple of (float, float), or None
        Time spans, s, in which the autopilot was in the mode an external controller flies
        it in (GUIDED, OFFBOARD); None when the log says nothing about modes.
    """

    source: str
    pose: Series | None
    pose_source: PoseSource
    rotors: tuple[Series, ...]
    warnings: tuple[str, ...] = ()
    truth: dict | None = None
    pose_hint: str = ""
    control_spans: tuple[tuple[float, float], ...] | None = None


def combine_pose(source: str, position: Series, attitude: Series,
                 ned: bool = True) -> tuple[Series, list[str]]:
    """One pose series from separately timed position and attitude samples.

    Parameters
    ----------
    source : str
        The file, for messages.
    position : Series
        Positions (m = 3), m, world NED if `ned` else ENU.
    attitude : Series
        Quaternions ``[w, x, y, z]`` (m = 4), body FRD → world NED if `ned` else FLU → ENU.
    ned : bool
        Whether the inputs are in NED/FRD.

    Returns
    -------
    pose : Series
        At the position times inside the attitude time span, with the attitude
        interpolated (slerp) to them; in ENU/FLU.
    warnings : list of str
        From cleaning both inputs (see `repair_samples`).
    """
    tp, p, notes = repair_samples(position.t, position.values, source, position.label)
    ta, q, more = repair_samples(attitude.t, attitude.values, source, attitude.label)
    notes += more
    if tp.shape[0] < 2 or ta.shape[0] < 2:
        thin = position if tp.shape[0] < 2 else attitude
        raise LogFormatError(f"{source}: fewer than 2 usable {thin.label} samples")
    q, more = normalise_quaternions(q, ta, source, attitude.label)
    notes += more
    inside = (tp >= ta[0]) & (tp <= ta[-1])
    if not inside.any():
        raise LogFormatError(f"{source}: {position.label} and {attitude.label} samples do not "
                             "overlap in time")
    tp, p = tp[inside], p[inside]
    q = interpolate_quaternions(ta, q, tp)
    if ned:
        p, q = ned_to_enu(p), quaternion_ned_to_enu(q)
    label = f"{position.label} + {attitude.label}"
    return Series(tp, np.column_stack([p, q]), label), notes


def _inside(t: np.ndarray, window: tuple[float, float] | None, margin: int = 0) -> slice:
    """The samples of increasing times ``t`` inside ``window`` (plus ``margin`` each side)."""
    if window is None:
        return slice(None)
    lo = int(np.searchsorted(t, window[0], side="left"))
    hi = int(np.searchsorted(t, window[1], side="right"))
    return slice(max(lo - margin, 0), hi + margin)


def to_flight_data(streams: LogStreams, vehicle: VehicleConfig,
                   window: tuple[float, float] | None = None) -> FlightData:
    """Resample the rotor speeds to the pose times and check the result.

    Parameters
    ----------
    streams : LogStreams
        What a reader (and possibly `merge_pose`) found.
    vehicle : VehicleConfig
        The vehicle that flew.
    window : tuple of 2 float, optional
        Start and end, s, on the log's clock: only the pose samples inside are used, and
        the rotor speeds inside and their one sample either side (for the interpolation);
        everything outside, such as slow telemetry before a flight, is not checked.

    Returns
    -------
    FlightData
        Pose samples inside the time span covered by every rotor-speed series, with the
        rotor speeds linearly interpolated to them; checked by `validate_flight`.

    Raises
    ------
    LogFormatError
        No pose, too few rotor-speed samples, no overlap, or any failed check.
    """
    source = streams.source
    if streams.pose is None:
        hint = f" ({streams.pose_hint})" if streams.pose_hint else ""
        raise LogFormatError(f"{source}: no pose in the log{hint}; give a motion-capture pose "
                             "file to merge")
    if not streams.rotors:
        raise LogFormatError(f"{source}: no rotor speeds or motor outputs in {source}")
    pose = streams.pose
    t, values, notes = repair_samples(pose.t, pose.values, source, pose.label)
    inside = _inside(t, window)
    if window is not None and t[inside].shape[0] < 2:
        span = f"t = {t[0]:.3f} to {t[-1]:.3f} s" if t.shape[0] else "no samples"
        raise LogFormatError(f"{source}: fewer than 2 pose samples in the window t = "
                             f"{window[0]:.3f} to {window[1]:.3f} s (the log has {span})")
    t, values = t[inside], values[inside]
    q, more = normalise_quaternions(values[:, 3:7], t, source, pose.label)
    values = np.column_stack([values[:, :3], q])
    notes = [*streams.warnings, *notes, *more]
    columns: list[tuple[np.ndarray, np.ndarray]] = []
    gaps = [np.empty((0, 2))]
    lo, hi = -np.inf, np.inf
    for series in streams.rotors:
        ts, vs, more = repair_samples(series.t, series.values, source, series.label)
        inside = _inside(ts, window, margin=1)
        ts, vs = ts[inside], vs[inside]
        notes += more
        if ts.shape[0] < 2:
            raise LogFormatError(f"{source}: fewer than 2 usable {series.label} samples")
        notes += check_sampling(ts, source, series.label)
        gaps.append(long_gaps(ts))
        lo, hi = max(lo, ts[0]), min(hi, ts[-1])
        columns.append((ts, vs))
    keep = (t >= lo) & (t <= hi)
    if not keep.any():
        span = f"t = {t[0]:.3f} to {t[-1]:.3f} s" if t.shape[0] else "no samples"
        raise LogFormatError(f"{source}: the pose ({span}) and the rotor speeds (t = {lo:.3f} "
                             f"to {hi:.3f} s) do not overlap in time")
    t, values = t[keep], values[keep]
    speeds = InputSamples(tuple(columns)).interpolate(t)
    data = FlightData(t=t, position=values[:, :3], quaternion=values[:, 3:7],
                      rotor_speeds=speeds, source=source,
                      pose_source=streams.pose_source,
                      truth=streams.truth, warnings=tuple(notes),
                      inputs=InputSamples(tuple(columns)))
    return validate_flight(data, vehicle, np.vstack(gaps))
