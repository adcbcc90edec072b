"""Checks applied to every flight before a reader returns it.

Problems the estimator cannot work around are errors (`LogFormatError`, one line naming
the file, exit code 2): a rotor count other than the vehicle config's, rotor speeds in
the wrong unit (rpm, rev/s, normalised outputs), less than `MIN_DURATION` of data, attitudes
far from unit quaternions (slow sampling is not refused). A gap longer than `MAX_GAP` (see
`gap_limit`) splits the flight into segments (`FlightData.segment_starts`), and segments
shorter than `MIN_DURATION` are dropped, with a note. Problems that can be repaired
are repaired and reported with counts as warnings: rows with NaN dropped, out-of-order
timestamps sorted, duplicate timestamps dropped, short gaps, slightly non-unit
quaternions normalised, a pose frozen in flight or a stuck or dead rotor
(`mavsysid.estimation.readers.unphysical_samples`) left out as a gap.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mavsysid.estimation.flight_data import MIN_DURATION, FlightData
from mavsysid.estimation.readers.unphysical_samples import (
    FLYING_THRUST,
    attitude_jumps,
    drop_unphysical_samples,
    frozen_samples,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import collective_thrust

from mavsysid.errors import LogFormatError

__all__ = [
    "FLYING_THRUST",
    "HOVER_FACTOR",
    "MAX_GAP",
    "QUATERNION_ERROR",
    "QUATERNION_WARNING",
    "check_sampling",
    "frozen_samples",
    "gap_limit",
    "long_gaps",
    "normalise_quaternions",
    "repair_samples",
    "split_segments",
    "validate_flight",
]

#: Longest gap between samples the estimator may bridge, s.
MAX_GAP = 0.2
#: Hover thrust Σ c_T n² off from m g by more than this factor means a unit error.
HOVER_FACTOR = 5.0
#: Quaternion norms off by more than this are reported when normalised.
QUATERNION_WARNING = 1e-3
#: Quaternion norms off by more than this are not attitudes: a wrong column or unit.
QUATERNION_ERROR = 0.1

# Hover ratio Σ c_T n² / (m g) that rotor speeds in rpm or rev/s instead of rad/s give.
_RPM_RATIO = (60.0 / (2.0 * np.pi)) ** 2
_REV_RATIO = (1.0 / (2.0 * np.pi)) ** 2


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def repair_samples(t: np.ndarray, values: np.ndarray, source: str,
                   what: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Drop non-finite rows, sort by time and drop duplicate timestamps.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s.
    values : ndarray, shape (N, m)
        The samples.
    source : str
        The file, for messages.
    what : str
        What the samples are ("pose", "ESC rpm", …), for messages.

    Returns
    -------
    t : ndarray, shape (M,)
        Strictly increasing.
    values : ndarray, shape (M, m)
    warnings : list of str
        One line per repair, with counts.
    """
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float).reshape(t.shape[0], -1)
    notes: list[str] = []
    finite = np.isfinite(t) & np.isfinite(values).all(axis=1)
    if not finite.all():
        bad = int((~finite).sum())
        notes.append(f"{source}: dropped {_plural(bad, 'row')} of {what} samples with NaN "
                     f"or infinite values (of {t.shape[0]})")
        t, values = t[finite], values[finite]
    backwards = int((np.diff(t) < 0.0).sum())
    if backwards:
        # Stable, so that of two samples with one timestamp the first logged is kept.
        order = np.argsort(t, kind="stable")
        t, values = t[order], values[order]
        notes.append(f"{source}: {_plural(backwards, 'timestamp')} of {what} samples out of "
                     "order; sorted by time")
    repeat = np.concatenate([[False], np.diff(t) == 0.0])
    if repeat.any():
        notes.append(f"{source}: dropped {_plural(int(repeat.sum()), 'sample')} of {what} "
                     "with a duplicate timestamp")
        t, values = t[~repeat], values[~repeat]
    # A jittered clock can stamp two samples a microsecond apart, a period's motion in
    # no time, which no model follows: keep the first, as of equal stamps.
    close = np.concatenate([[False], np.diff(t) < 0.05 * np.median(np.diff(t))]) if (
        t.shape[0] > 2) else np.zeros(t.shape[0], dtype=bool)
    if close.any():
        notes.append(f"{source}: dropped {_plural(int(close.sum()), 'sample')} of {what} "
                     "stamped within 5 % of a sample period after the previous one")
        t, values = t[~close], values[~close]
    return t, values, notes


def normalise_quaternions(q: np.ndarray, t: np.ndarray, source: str,
                          what: str) -> tuple[np.ndarray, list[str]]:
    """Normalise attitude quaternions, shape (N, 4), reporting or rejecting bad norms.

    Norm errors up to `QUATERNION_WARNING` are rounding and pass silently; up to
    `QUATERNION_ERROR` they are normalised with a warning; beyond, `LogFormatError`.
    """
    norm = np.linalg.norm(q, axis=1)
    off = np.abs(norm - 1.0)
    wrong = off > QUATERNION_ERROR
    if wrong.any():
        i = int(np.argmax(wrong))
        raise LogFormatError(
            f"{source}: {_plural(int(wrong.sum()), 'attitude quaternion')} of {what} with "
            f"norm far from 1 (first at t = {t[i]:.3f} s, norm {norm[i]:.4g}); the attitude "
            "columns hold something else than a unit quaternion [w, x, y, z]")
    notes = []
    fixed = int((off > QUATERNION_WARNING).sum())
    if fixed:
        notes.append(f"{source}: normalised {_plural(fixed, 'attitude quaternion')} of {what} "
                     f"with norm off by more than {QUATERNION_WARNING:g} (largest "
                     f"{off.max():.3g})")
    return q / norm[:, None], notes


def gap_limit(period: float) -> float:
    """The longest step, s, bridged in samples of median step ``period``, s.

    `MAX_GAP` (one sample period for series sampled more slowly) plus half a sample period
    of tolerance: timestamps carry clock ticks and jitter, so a gap of exactly `MAX_GAP`
    must not count as longer.
    """
    return max(MAX_GAP, period) + 0.5 * period


def long_gaps(t: np.ndarray) -> np.ndarray:
    """The gaps too long to bridge in strictly increasing times, shape (N ≥ 2,), s.

    Returns
    -------
    ndarray, shape (G, 2)
        The last sample time before and the first after each gap (see `gap_limit`), s.
    """
    dt = np.diff(t)
    wide = dt > gap_limit(float(np.median(dt)))
    return np.column_stack([t[:-1][wide], t[1:][wide]])


def check_sampling(t: np.ndarray, source: str, what: str) -> list[str]:
    """Check gaps in strictly increasing sample times, shape (N ≥ 2,), s.

    Returns warnings for gaps between 2 sample periods (the median step) and the
    `gap_limit` (longer gaps split the flight, see `split_segments`); and a
    note, not an error, for sampling slower than 1 / `MAX_GAP`.
    """
    dt = np.diff(t)
    period = float(np.median(dt))
    # Slow sampling is not refused: it is information, only less of it. Slow inputs are
    # interpolated with a modelled error (`mavsysid.estimation.input_noise`).
    slow = ([f"{source}: {what} sampled only every {period:.3g} s (slower than every "
             f"{MAX_GAP:g} s): used, with the larger uncertainty that leaves between "
             "samples"] if period > MAX_GAP else [])
    long = (dt > 2.0 * period) & (dt <= gap_limit(period))
    if not long.any():
        return slow
    i = int(np.argmax(np.where(long, dt, 0.0)))
    return [*slow,
            f"{source}: {_plural(int(long.sum()), 'gap')} in the {what} samples longer than "
            f"2 sample periods ({2.0 * period:.3g} s), longest {dt[i]:.3g} s after "
            f"t = {t[i]:.3f} s"]


def split_segments(t: np.ndarray, gaps: np.ndarray, source: str
                   ) -> tuple[np.ndarray, tuple[int, ...], list[str]]:
    """Split sample times at gaps too long to bridge; drop segments that are too short.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing sample times, s.
    gaps : ndarray, shape (G, 2)
        Gaps (last time before, first time after), s, of this or any other input series:
        samples strictly inside one are dropped, and a segment ends before each.
    source : str
        The file, for messages.

    Returns
    -------
    keep : ndarray of bool, shape (N,)
        The samples kept.
    starts : tuple of int
        Index, into the kept samples, of each segment's first sample (``(0,)``: one).
    notes : list of str
        What was split and dropped, one line each.
    """
    keep = np.ones(t.shape[0], dtype=bool)
    breaks = np.zeros(t.shape[0], dtype=bool)
    for a, b in gaps:
        keep &= ~((t > a) & (t < b))
    tk = t[keep]
    for a, b in gaps:
        # A segment starts at the first sample at or after the gap's end.
        i = int(np.searchsorted(tk, b))
        if 0 < i < tk.shape[0] and tk[i - 1] <= a:
            breaks[i] = True
    starts = [0, *np.flatnonzero(breaks[:tk.shape[0]]).tolist()]
    if len(starts) == 1 and keep.all():
        return keep, (0,), []
    bounds = list(zip(starts, [*starts[1:], tk.shape[0]], strict=True))
    longest = float(np.max(gaps[:, 1] - gaps[:, 0]))
    notes = [f"{source}: {_plural(len(gaps), 'gap')} too long to bridge (longest "
             f"{longest:.3g} s) split the flight into {_plural(len(bounds), 'segment')}; the "
             "filter restarts the vehicle states after each gap and carries θ across it"]
    short = [(i, j) for i, j in bounds if tk[j - 1] - tk[i] < MIN_DURATION]
    for i, j in short:
        notes.append(f"{source}: dropped the segment t = {tk[i]:.3f} to {tk[j - 1]:.3f} s, "
                     f"shorter than {MIN_DURATION:g} s")
    index = np.flatnonzero(keep)
    new_starts, count = [], 0
    for i, j in bounds:
        if (i, j) in short:
            keep[index[i:j]] = False
        else:
            new_starts.append(count)
            count += j - i
    return keep, tuple(new_starts) or (0,), notes


def _check_rotor_count(data: FlightData, vehicle: VehicleConfig) -> None:
    if data.rotor_count != vehicle.rotor_count:
        raise LogFormatError(
            f"{data.source}: the log has rotor speeds of {data.rotor_count} rotors, the "
            f"vehicle config {vehicle.source or vehicle.name} has {vehicle.rotor_count} "
            "rotors; use the config of the vehicle that flew")


def _check_hover(data: FlightData, vehicle: VehicleConfig) -> None:
    """Compare the median Σ c_T n² with m g to catch rotor speeds in the wrong unit."""
    n = data.rotor_speeds
    spinning = (n > 0.0).any(axis=1)
    if not spinning.any():
        raise LogFormatError(f"{data.source}: the rotor speeds are zero throughout; the "
                             "rotors never spun in this log")
    # Samples with the rotors stopped or idling (on the ground, disarmed, spool-up) say
    # nothing about units: only those above 1 % of the log's high thrust count.
    thrust = collective_thrust(vehicle.parameters.c_T, n[spinning])
    thrust = thrust[thrust >= 0.01 * np.percentile(thrust, 95)]
    ratio = float(np.median(thrust)) / (vehicle.mass * GRAVITY)
    if 1.0 / HOVER_FACTOR <= ratio <= HOVER_FACTOR:
        return
    found = (f"the median thrust Σ c_T n² is {ratio:.3g} × m g (nominal c_T and mass of "
             f"{vehicle.source or vehicle.name})")
    top = float(np.max(np.abs(n)))
    if top <= 1.0:
        unit = (f"rotor speeds are at most {top:.3g}: they look like normalised motor outputs "
                "(0..1), not rad/s; log actual rotor speeds or convert the outputs with the "
                "motor curve")
    elif _RPM_RATIO / 3.0 <= ratio <= _RPM_RATIO * 3.0:
        unit = (f"{found}, close to (60/2π)² = {_RPM_RATIO:.3g}: the rotor speeds look like "
                "rpm; divide them by 60/2π = 9.549 to get rad/s")
    elif _REV_RATIO / 3.0 <= ratio <= _REV_RATIO * 3.0:
        unit = (f"{found}, close to (1/2π)² = {_REV_RATIO:.3g}: the rotor speeds look like "
                "rev/s; multiply them by 2π to get rad/s")
    else:
        unit = (f"{found}, not within a factor {HOVER_FACTOR:g} of 1: check that the rotor "
                "speeds are in rad/s and that c_T and the mass in the vehicle config are right")
    raise LogFormatError(f"{data.source}: {unit}")


def validate_flight(data: FlightData, vehicle: VehicleConfig,
                    gaps: np.ndarray | None = None) -> FlightData:
    """Apply every check of this module to a flight.

    Parameters
    ----------
    data : FlightData
        A flight as a reader assembled it (times need not be sorted yet).
    vehicle : VehicleConfig
        The vehicle that flew: rotor count, nominal c_T and mass.
    gaps : ndarray, shape (G, 2), optional
        Gaps too long to bridge in the rotor-speed series (`long_gaps`), s; the pose's
        own are found here.

    Returns
    -------
    FlightData
        Repaired (see `repair_samples`, `normalise_quaternions`), split into segments at
        long gaps (`split_segments`), with the warnings of the repairs, of short gaps and
        of the split appended to ``data.warnings``.

    Raises
    ------
    LogFormatError
        One line naming ``data.source`` and the problem.
    """
    source = data.source
    _check_rotor_count(data, vehicle)
    k = data.rotor_count
    stacked = np.column_stack([data.position, data.quaternion, data.rotor_speeds])
    t, stacked, notes = repair_samples(data.t, stacked, source, "pose and rotor speed")
    if t.shape[0] < 2:
        raise LogFormatError(f"{source}: {_plural(t.shape[0], 'usable sample')}; need at least "
                             f"{MIN_DURATION:g} s of pose and rotor speeds")
    t, stacked, more = drop_unphysical_samples(t, stacked, source, vehicle, MAX_GAP)
    notes += more
    q, more = normalise_quaternions(stacked[:, 3:7], t, source, "pose")
    notes += more
    duration = float(t[-1] - t[0])
    if duration < MIN_DURATION:
        raise LogFormatError(f"{source}: only {duration:.3g} s of pose and rotor speeds (t = "
                             f"{t[0]:.3f} to {t[-1]:.3f} s); need at least {MIN_DURATION:g} s")
    notes += check_sampling(t, source, "pose")
    jumps, more = attitude_jumps(t, q, source)
    notes += more
    gaps = np.vstack([long_gaps(t), jumps, *(() if gaps is None else (gaps,))])
    keep, starts, more = split_segments(t, gaps, source)
    notes += more
    if not keep.any():
        raise LogFormatError(f"{source}: no stretch of {MIN_DURATION:g} s of pose and rotor "
                             f"speeds without a gap longer than {MAX_GAP:g} s")
    t, stacked, q = t[keep], stacked[keep], q[keep]
    repaired = dataclasses.replace(data, t=t, position=stacked[:, :3], quaternion=q,
                                   rotor_speeds=stacked[:, 7:7 + k],
                                   warnings=(*data.warnings, *notes), segment_starts=starts)
    _check_hover(repaired, vehicle)
    return repaired
