"""Where a flight comes from: each log kind into `LogStreams`, the calibration window, and
an external motion-capture pose merged on its own clock.

**Pose logs** (`read_pose_csv`): mavsysid's own ``pose.csv`` is already in the project's
conventions (world ENU, body FLU, rad/s in the config's rotor order) and is read strictly
by `mavsysid.formats.poselog.read_pose_log`; a simulated flight's ``meta.json`` next to it
supplies the truth.

**Autopilot logs** (`read_autopilot_log`, ``.tlog``, ``.ulg``, ``.bin``). Each format's
module reads its log into a `ParsedLog` in the log's own conventions (NED/FRD and the
autopilot's motor numbering). Here the pose goes into ENU/FLU (`mavsysid.vehicle.frames`;
the autopilot's separately timed position and attitude combined into one pose,
`combine_pose`) and the motor outputs into the config's rotor order
(`rotors_in_config_order`): more motor outputs than rotors are refused unless the vehicle
names its autopilot frame, through which (`mavsysid.vehicle.motor_order`) they are put
into the config's order.

**The calibration window** (`choose_window`). A real log holds take-off, landing and time
on the ground around the part flown for identification. In this order: the window given
(``--start``/``--end``, s on the log's clock); the trajectory `mavsysid stream` flew
(``trajectory_window`` of the ``meta.json`` beside the log); the longest span in the mode
an external controller flies it in (GUIDED, OFFBOARD: `control_spans`); else the whole
log. It says which and why in an ``info:`` note.

**An external pose** (``--pose``, `merge_pose`): the merged flight keeps the flight log's
clock and rotor speeds and takes its pose from the motion-capture file, shifted by the
clock offset, given or found by `estimate_time_offset`. The two clocks share no
timestamps, so the offset comes from the motion: when the flight log has a pose of its
own, both sides give the body angular-rate magnitude |ω| (frame independent); with rotor
speeds only, the motion capture's specific force along the body z axis is correlated with
Σ n². The lag of the correlation's peak, refined by a parabola, is the offset.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mavsysid.estimation.flight import Imu, ImuSeries
from mavsysid.estimation.readers.samples import (
    LogStreams,
    combine_pose,
    normalise_quaternions,
    repair_samples,
)
from mavsysid.formats.flight_dir import STREAM_SOURCE, read_meta
from mavsysid.formats.motor_curve import check_curve_against_rpm
from mavsysid.formats.parsed_log import ModeChanges, ParsedLog, Series
from mavsysid.formats.poselog import read_external_pose, read_pose_log
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.frames import frd_to_flu, ned_to_enu, quaternion_ned_to_enu
from mavsysid.vehicle.motor_order import AUTOPILOT_FRAMES, MotorOrderError, output_to_rotor
from mavsysid.vehicle.rotation import (
    interpolate_quaternions,
    quat_conjugate,
    quat_log,
    quat_multiply,
    quat_to_matrix,
)
from scipy.signal import correlate, correlation_lags, savgol_filter

from mavsysid.errors import ConfigError, InputError, LogFormatError

__all__ = ["CONTROLLED_MODES", "MIN_CORRELATION", "TimeWindow", "choose_window", "control_spans",
           "estimate_time_offset", "longest_span", "merge_pose", "meta_window",
           "read_autopilot_log", "read_pose_csv", "rotors_in_config_order", "spans_of"]


#: Autopilot modes in which an external controller (the streamer) flies the vehicle.
CONTROLLED_MODES = frozenset({"GUIDED", "GUIDED_NOGPS", "OFFBOARD"})


@dataclass(frozen=True)
class TimeWindow:
    """A window of a log's time, s on its clock; None: open on that side.

    Attributes
    ----------
    start, end : float or None
        s.
    reason : str
        Why this window, for the note.
    """

    start: float | None
    end: float | None
    reason: str

    @property
    def bounds(self) -> tuple[float, float]:
        """``(start, end)`` with open sides as ∓∞, s."""
        return (-math.inf if self.start is None else self.start,
                math.inf if self.end is None else self.end)

    def describe(self) -> str:
        """``t = a to b s`` with "start"/"end" for open sides."""
        a = "the start" if self.start is None else f"{self.start:.3f}"
        b = "the end" if self.end is None else f"{self.end:.3f} s"
        return f"t = {a} to {b}"


def spans_of(t: np.ndarray, active: np.ndarray, events: bool,
             end: float) -> list[tuple[float, float]]:
    """Contiguous spans of ``active`` samples at times ``t`` (increasing), s.

    ``events``: each sample is a mode change, so a span lasts until the next inactive
    sample (or ``end``); else the samples are periodic reports and a span runs from its
    first to its last active report (conservative by up to one report period).
    """
    spans = []
    i, n = 0, len(t)
    while i < n:
        if not active[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and active[j + 1]:
            j += 1
        stop = (t[j + 1] if j + 1 < n else end) if events else t[j]
        spans.append((float(t[i]), float(stop)))
        i = j + 1
    return spans


def longest_span(spans: list[tuple[float, float]] | tuple[tuple[float, float], ...]
                 ) -> tuple[float, float] | None:
    """The longest of ``spans`` (the first of equals), or None if there is none of length > 0."""
    best = max(spans, key=lambda s: s[1] - s[0], default=None)
    return None if best is None or best[1] <= best[0] else best


def meta_window(path: Path) -> tuple[float, float | None] | None:
    """``trajectory_window`` (start, end) of the ``meta.json`` beside ``path``, s, or None.

    ``end`` is None when the trajectory was cut off without an end being recorded.
    """
    meta_path = path.parent / "meta.json"
    if not meta_path.is_file():
        return None
    window = read_meta(meta_path).get("trajectory_window")
    if not isinstance(window, dict) or not isinstance(window.get("start"), (int, float)):
        return None
    end = window.get("end")
    return float(window["start"]), float(end) if isinstance(end, (int, float)) else None


def control_spans(modes: ModeChanges) -> tuple[tuple[float, float], ...]:
    """The spans of a log's modes in which an external controller flies (`CONTROLLED_MODES`).

    Parameters
    ----------
    modes : ModeChanges
        The log's modes, as its format's reader gives them.

    Returns
    -------
    tuple of (float, float)
        Start and end of each span, s (see `spans_of`).
    """
    active = np.array([mode in CONTROLLED_MODES for mode in modes.modes])
    return tuple(spans_of(modes.t, active, modes.events, modes.end))


def choose_window(path: Path, start: float | None, end: float | None,
                  control_spans: Callable[[], tuple[tuple[float, float], ...] | None]
                  ) -> TimeWindow | None:
    """The window to use (see the module docstring), or None for the whole log.

    Parameters
    ----------
    path : Path
        The flight log (its directory may hold ``meta.json``).
    start, end : float or None
        The window asked for, s; either given overrides the defaults.
    control_spans : callable
        Returns the log's GUIDED/OFFBOARD spans, s (None: the log has no mode
        information); called only when needed.
    """
    if start is not None or end is not None:
        if start is not None and end is not None and not start < end:
            raise InputError(f"{path}: window --start {start:g} s to --end {end:g} s: "
                             "expected start < end")
        return TimeWindow(start, end, "given by --start/--end")
    found = meta_window(path)
    if found is not None:
        return TimeWindow(found[0], found[1], "the trajectory flown by mavsysid stream "
                          "(meta.json trajectory_window)")
    span = longest_span(control_spans() or ())
    if span is not None:
        return TimeWindow(span[0], span[1], "the longest span in GUIDED/OFFBOARD mode in the "
                          "log, the part flown under external control")
    return None


#: Below this peak correlation the offset is not trusted (an error asks for it instead).
MIN_CORRELATION = 0.3
# Differentiation spans, s: differentiated motion-capture noise would otherwise dominate.
_RATE_BASELINE = 0.05
_ACCELERATION_WINDOW = 0.2


def _period(t: np.ndarray) -> float:
    return float(np.median(np.diff(t)))


def _grid(t: np.ndarray, dt: float) -> np.ndarray:
    return t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)


def _rate_signal(t: np.ndarray, q: np.ndarray, dt: float) -> tuple[float, np.ndarray]:
    """|ω|, rad/s, on a uniform grid of step dt: (time of the first value, values).

    The attitude is resampled first and differenced over ±`_RATE_BASELINE`: a longer
    baseline divides the attitude noise by more than smoothing a one-step rate would.
    """
    grid = _grid(t, dt)
    qg = interpolate_quaternions(t, q, grid)
    h = max(1, round(_RATE_BASELINE / dt))
    if grid.shape[0] <= 2 * h:
        raise LogFormatError("too few attitude samples to find the clock offset")
    turn = quat_log(quat_multiply(quat_conjugate(qg[:-2 * h]), qg[2 * h:]))
    return float(grid[h]), np.linalg.norm(turn, axis=1) / (2 * h * dt)


def _specific_force_signal(t: np.ndarray, pose: np.ndarray, dt: float,
                           label: str) -> tuple[float, np.ndarray]:
    """e_z^B · (a − g), m/s², from motion capture, on a uniform grid of step dt."""
    grid = _grid(t, dt)
    p = np.column_stack([np.interp(grid, t, pose[:, i]) for i in range(3)])
    q = interpolate_quaternions(t, pose[:, 3:7], grid)
    window = max(5, 2 * round(_ACCELERATION_WINDOW / dt / 2) + 1)
    if window > grid.shape[0]:
        raise LogFormatError(f"{label}: too few samples to find its clock offset")
    a = savgol_filter(p, window, 3, deriv=2, delta=dt, axis=0)
    a[:, 2] += GRAVITY
    return float(grid[0]), np.sum(quat_to_matrix(q)[:, :, 2] * a, axis=1)


def _thrust_signal(rotors: tuple[Series, ...], dt: float) -> tuple[float, np.ndarray]:
    """Σ n², (rad/s)², over the span all rotor series cover, on a uniform grid of step dt."""
    clean = [repair_samples(s.t, s.values, "", s.label)[:2] for s in rotors]
    lo = max(t[0] for t, _ in clean)
    hi = min(t[-1] for t, _ in clean)
    grid = _grid(np.array([lo, hi]), dt)
    total = sum(np.interp(grid, t, v[:, j]) ** 2 for t, v in clean for j in range(v.shape[1]))
    return float(grid[0]), np.asarray(total)


def _normalised_correlation(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pearson correlation of a[n + ℓ] with b[n] over their overlap, for every lag ℓ.

    Means and variances are those of the overlapping parts: normalising by the whole
    signals instead biases the peak when one recording spans more of the motion.
    """
    a, b = a - a.mean(), b - b.mean()
    m, n = a.shape[0], b.shape[0]
    lags = correlation_lags(m, n, mode="full")
    start_b, stop_b = np.maximum(0, -lags), np.minimum(n, m - lags)
    count = stop_b - start_b
    cum_a, cum_aa = (np.concatenate([[0.0], np.cumsum(x)]) for x in (a, a * a))
    cum_b, cum_bb = (np.concatenate([[0.0], np.cumsum(x)]) for x in (b, b * b))
    s_a = cum_a[stop_b + lags] - cum_a[start_b + lags]
    s_aa = cum_aa[stop_b + lags] - cum_aa[start_b + lags]
    s_b, s_bb = cum_b[stop_b] - cum_b[start_b], cum_bb[stop_b] - cum_bb[start_b]
    s_ab = correlate(a, b, mode="full", method="fft")
    var = (s_aa - s_a**2 / count) * (s_bb - s_b**2 / count)
    r = (s_ab - s_a * s_b / count) / np.sqrt(np.maximum(var, 1e-300))
    return lags, r


def _best_lag(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Lag ℓ, in samples, maximising the correlation of a[n + ℓ] with b[n], and its peak."""
    lags, r = _normalised_correlation(a, b)
    overlap = np.minimum(b.shape[0], a.shape[0] - lags) - np.maximum(0, -lags)
    # Short overlaps correlate well by chance: require half the shorter recording.
    r = np.where(overlap >= 0.5 * min(a.shape[0], b.shape[0]), r, -np.inf)
    i = int(np.argmax(r))
    frac = 0.0
    if 0 < i < r.shape[0] - 1 and np.isfinite(r[i - 1]) and np.isfinite(r[i + 1]):
        curvature = r[i - 1] - 2.0 * r[i] + r[i + 1]
        if curvature < 0.0:
            frac = 0.5 * (r[i - 1] - r[i + 1]) / curvature
    return float(lags[i] + frac), float(r[i])


def estimate_time_offset(log: LogStreams, mocap: Series, label: str) -> tuple[float, str]:
    """Offset to add to motion-capture times to put them on the flight log's clock.

    Parameters
    ----------
    log : LogStreams
        The flight log: its pose if it has one, else its rotor speeds.
    mocap : Series
        Clean motion-capture pose (strictly increasing t, m = 7, ENU/FLU).
    label : str
        The pose file, for messages.

    Returns
    -------
    offset : float
        s, such that t_log = t_mocap + offset.
    how : str
        The signals correlated and the peak correlation, for the info line.

    Raises
    ------
    LogFormatError
        The peak correlation is below `MIN_CORRELATION`.
    """
    if log.pose is not None:
        t, pose, _ = repair_samples(log.pose.t, log.pose.values, "", log.pose.label)
        q = pose[:, 3:7] / np.linalg.norm(pose[:, 3:7], axis=1, keepdims=True)
        dt = min(_period(t), _period(mocap.t))
        start_a, a = _rate_signal(t, q, dt)
        start_b, b = _rate_signal(mocap.t, mocap.values[:, 3:7], dt)
        what = "body angular-rate magnitude"
    else:
        dt = min(min(_period(s.t) for s in log.rotors), _period(mocap.t))
        start_a, a = _thrust_signal(log.rotors, dt)
        start_b, b = _specific_force_signal(mocap.t, mocap.values, dt, label)
        what = "Σ n² against the motion capture's body-z specific force"
    lag, peak = _best_lag(a, b)
    if peak < MIN_CORRELATION:
        raise LogFormatError(
            f"{label}: cannot find its clock offset to {log.source}: the {what} correlate "
            f"at {peak:.2f} at best; give the time offset explicitly")
    offset = start_a - start_b + lag * dt
    return offset, f"cross-correlation of the {what}, peak {peak:.2f}"


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
        combined, more motor outputs than rotors without an autopilot frame, or commanded
        rotor speeds the log's own ESC rpm contradicts
        (`mavsysid.formats.motor_curve.check_curve_against_rpm`).
    """
    log = read(path, vehicle)
    log_rotors, scale_sigma, curve_notes = _curve_fitted(log, vehicle, path)
    notes = list(log.notes)
    pose = None
    if log.pose is not None:
        p, q = log.pose.values[:, :3], log.pose.values[:, 3:7]
        pose = Series(log.pose.t, np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)]),
                      log.pose.label)
    elif log.position is not None and log.attitude is not None:
        pose, combined = combine_pose(log.source, log.position, log.attitude)
        notes += combined
    rotors, ordered = rotors_in_config_order(log.source, log_rotors, vehicle)
    return LogStreams(source=log.source, pose=pose, pose_source=log.pose_source, rotors=rotors,
                      warnings=(*notes, *log.rotor_notes, *curve_notes, *ordered),
                      pose_hint=log.pose_hint,
                      control_spans=None if log.modes is None else control_spans(log.modes),
                      imu=_autopilot_imu(log, vehicle), rotor_scale_sigma=scale_sigma)


def _curve_fitted(log: ParsedLog, vehicle: VehicleConfig, path: Path
                  ) -> tuple[tuple[Series, ...], float, list[str]]:
    """The log's rotor speeds, those through the motor curve rescaled to its own ESC rpm
    where it has some (`mavsysid.formats.motor_curve.check_curve_against_rpm`); the
    relative σ of their scale (0: measured); a note of the fit."""
    commanded = [r for r in log.rotors if all(r is not e for e in log.esc_speeds)]
    if not commanded:
        return log.rotors, 0.0, []
    if len(commanded) != 1 or len(log.esc_speeds) != 1:
        return log.rotors, vehicle.motor.curve_sigma, []
    fit = check_curve_against_rpm(commanded[0], log.esc_speeds[0],
                                  f"{path}: {commanded[0].label} against {log.esc_speeds[0].label}")
    if fit is None:
        return log.rotors, vehicle.motor.curve_sigma, []
    scaled = Series(commanded[0].t, commanded[0].values * fit.factor, commanded[0].label)
    rotors = tuple(scaled if r is commanded[0] else r for r in log.rotors)
    note = (f"{path}: the motor curve's scale fitted to the log's own ESC rpm "
            f"({log.esc_speeds[0].label}, {fit.samples} samples): rotor speeds × "
            f"{fit.factor:.4f} ± {fit.sigma:.4f} (the file's rotor_speed_max × that)")
    return rotors, fit.sigma / fit.factor, [note]


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
    imu = None
    if log.gyro is not None or log.accel is not None:
        imu = Imu(None if log.gyro is None else ImuSeries(log.t, log.gyro, None, "gyro_x..z"),
                  None if log.accel is None else ImuSeries(log.t, log.accel, None, "acc_x..z"),
                  _imu_position(vehicle, None))
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source,
                      rotors=rotors, warnings=notes, truth=truth, imu=imu)


def _imu_position(vehicle: VehicleConfig, logged: tuple[float, float, float] | None
                  ) -> np.ndarray | None:
    """The IMU's offset from the CoG, body FLU: the vehicle file's, else the log's (FRD)."""
    if vehicle.imu_position is not None:
        return np.asarray(vehicle.imu_position, dtype=float)
    return None if logged is None else frd_to_flu(np.asarray(logged, dtype=float))


def _autopilot_imu(log: ParsedLog, vehicle: VehicleConfig) -> Imu | None:
    """The log's IMU in body FLU, with its stated low-pass and position."""
    if log.gyro is None and log.accel is None:
        return None
    cutoffs = (None, None) if log.imu_filter is None else (
        log.imu_filter.gyro_cutoff_hz, log.imu_filter.accel_cutoff_hz)
    sensors = [None if s is None else ImuSeries(s.t, frd_to_flu(s.values), cutoff, s.label)
               for s, cutoff in zip((log.gyro, log.accel), cutoffs, strict=True)]
    return Imu(sensors[0], sensors[1], _imu_position(vehicle, log.imu_position))


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
                      warnings=(*log.warnings, *notes), truth=log.truth, imu=log.imu,
                      rotor_scale_sigma=log.rotor_scale_sigma)
