"""From a log's streams to a checked `FlightData`: resampling, repairs and refusals.

Each reader returns `LogStreams`: the pose samples (ENU/FLU) and one or more rotor-speed
series (rad/s, the config's rotor order), each on its own clock. `to_flight_data`
resamples the rotor speeds to the pose times (pose samples outside their span are
dropped) and checks the result (`validate_flight`). Keeping the streams apart until then
lets ``--pose`` swap in a motion-capture pose first.

**Refusals** (`LogFormatError`, one line naming the file, exit 2): a rotor count other
than the vehicle config's, rotor speeds in the wrong unit (rpm, rev/s, normalised
outputs), less than `MIN_DURATION` of data, attitudes far from unit quaternions. A gap
longer than `MAX_GAP` (`gap_limit`) splits the flight into segments; segments shorter than
`MIN_DURATION` are dropped, with a note.

**Repairs**, reported with counts as warnings: rows with NaN dropped, out-of-order
timestamps sorted, duplicate timestamps dropped, short gaps, slightly non-unit
quaternions normalised; IMU samples repeating the previous one exactly (held on the pose's
rows, or stuck) left out (`clean_imu`).

**Samples no working sensor produces in flight** (`drop_unphysical_samples`): a measured
position, attitude or set of rotor speeds never repeats to the last bit while the vehicle
flies, and a rotor that reads 0 while the others carry the vehicle has a dead channel.
Such samples (a stalled estimator, a lost motion-capture body, a dead ESC telemetry
channel) are left out as gaps, one note each; one rotor's dead readings, while the vehicle
keeps flying, are filled from the other rotors instead (`fill_dead_rotor`). On the ground
a signal may well stand still, so only runs mostly at flying thrust count.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.flight import MIN_DURATION, FlightData, Imu, ImuSeries, InputSamples
from mavsysid.formats.parsed_log import PoseSource, Series
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.frames import ned_to_enu, quaternion_ned_to_enu
from mavsysid.vehicle.mav_model import collective_thrust, rotor_thrust
from mavsysid.vehicle.rotation import (
    interpolate_quaternions,
    quat_conjugate,
    quat_log,
    quat_multiply,
)

from mavsysid.errors import LogFormatError

__all__ = [
    "ACCEL_MEDIAN_RANGE",
    "FLYING_THRUST",
    "GYRO_GAIN_RANGE",
    "GYRO_SIZE_MAX",
    "HOVER_FACTOR",
    "MAX_BODY_RATE",
    "MAX_GAP",
    "MIN_LIVE_TIME",
    "QUATERNION_ERROR",
    "QUATERNION_WARNING",
    "LogStreams",
    "attitude_jumps",
    "check_sampling",
    "clean_imu",
    "combine_pose",
    "dead_rotor_samples",
    "drop_unphysical_samples",
    "fill_dead_rotor",
    "frozen_samples",
    "gap_limit",
    "long_gaps",
    "normalise_quaternions",
    "repair_samples",
    "split_segments",
    "to_flight_data",
    "validate_flight",
]


#: Σ c_T n² at or above this fraction of m g (nominal c_T) is flying, for `frozen_samples`.
FLYING_THRUST = 0.8
#: An attitude change between two samples faster than this, rad/s, is a discontinuity (a
#: clock that jumped back over logged samples, an estimator reset), not a turn: 2000 °/s is
#: the full scale of the gyroscopes multirotors fly with, and no multirotor turns faster.
MAX_BODY_RATE = np.deg2rad(2000.0)


def attitude_jumps(t: np.ndarray, q: np.ndarray, source: str
                   ) -> tuple[np.ndarray, list[str]]:
    """Steps between samples where the attitude turns faster than `MAX_BODY_RATE`.

    The rate of a fresh attitude is measured from the last fresh one before it: a held
    (repeated) attitude followed by a new one is a slow turn, not a jump.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing sample times, s.
    q : ndarray, shape (N, 4)
        Unit attitude quaternions.
    source : str
        The file, for messages.

    Returns
    -------
    gaps : ndarray, shape (G, 2)
        The sample times before and after each jump, s: the flight is split there, as at
        a gap too long to bridge.
    notes : list of str
        One line when there is any.
    """
    # A pose streamed at a lower rate (or lost packets) repeats; the turn since the last
    # fresh attitude took the whole time since then, not one sample period.
    fresh = np.flatnonzero(np.concatenate([[True], np.any(q[1:] != q[:-1], axis=1)]))
    cosine = np.clip(np.abs(np.sum(q[fresh[1:]] * q[fresh[:-1]], axis=1)), 0.0, 1.0)
    rate = np.full(t.shape[0] - 1, 0.0)
    rate[fresh[1:] - 1] = 2.0 * np.arccos(cosine) / (t[fresh[1:]] - t[fresh[:-1]])
    jump = np.flatnonzero(rate > MAX_BODY_RATE)
    if not jump.size:
        return np.empty((0, 2)), []
    i = int(jump[np.argmax(rate[jump])])
    return np.column_stack([t[jump], t[jump + 1]]), [
        f"{source}: the attitude jumps {_plural(jump.size, 'time')} faster than "
        f"{np.rad2deg(MAX_BODY_RATE):g} °/s between samples (largest {np.rad2deg(rate[i]):.3g} "
        f"°/s after t = {t[i]:.3f} s): a clock or estimator discontinuity, not a turn; the "
        "flight is split there"]


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """[a, b) index ranges of the True runs of a boolean array."""
    edges = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))


def frozen_samples(t: np.ndarray, values: np.ndarray, airborne: np.ndarray,
                   min_run: float) -> np.ndarray:
    """Samples repeating the previous one exactly, in airborne runs longer than ``min_run``.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing sample times, s.
    values : ndarray, shape (N, m)
        The signal (all m columns must repeat).
    airborne : ndarray of bool, shape (N,)
        Samples at flying thrust (`FLYING_THRUST`).
    min_run : float
        Shortest run counted, s (from its first sample, the last one that differs).

    Returns
    -------
    ndarray of bool, shape (N,)
        True for the repeats (not the first sample of a run).
    """
    same = np.concatenate([[False], (np.diff(values, axis=0) == 0.0).all(axis=1)])
    frozen = np.zeros(t.shape[0], dtype=bool)
    for a, b in _runs(same):
        if t[b - 1] - t[a - 1] > min_run and airborne[a - 1:b].mean() > 0.5:
            frozen[a:b] = True
    return frozen


def dead_rotor_samples(t: np.ndarray, n: np.ndarray, airborne: np.ndarray,
                       min_run: float) -> np.ndarray:
    """Samples where a rotor reads exactly 0 while the others carry the vehicle.

    A spinning-down motor passes through 0 only for an instant (the simulator's rotors, driven
    to their lower limit in hard yaw manoeuvres, dip to within 1 % of 0 but never read 0); a
    rotor reading 0 for longer, with the others at flying thrust, is a dead telemetry channel,
    or a stopped motor, which the flight's attitude then could not have held. Either way the
    rotor law cannot be fitted to it. (A ratio rule, "far below the others", would not do:
    aggressive flights drive single rotors to a few % of the others for a quarter second.)

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing sample times, s.
    n : ndarray, shape (N, k)
        Rotor speeds, rad/s.
    airborne : ndarray of bool, shape (N,)
        Samples where the other rotors carry flying thrust.
    min_run : float
        Shortest run counted, s.

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    zero = (n == 0.0).any(axis=1) & ~(n == 0.0).all(axis=1) & airborne
    dead = np.zeros(t.shape[0], dtype=bool)
    for a, b in _runs(zero):
        if t[b - 1] - t[a] > min_run:
            dead[a:b] = True
    return dead


def _stuck_rotor_samples(t: np.ndarray, n: np.ndarray, airborne: np.ndarray,
                         min_run: float) -> np.ndarray:
    """Rotor samples all repeating the previous row exactly, except at full speed.

    Every rotor at the log's top speed at once is a saturated climb, which may well last;
    any other row held exactly is a logger repeating its last message.
    """
    saturated = (n == n.max(axis=0)).all(axis=1)
    return frozen_samples(t, n, airborne & ~saturated, min_run)


#: Time at flying thrust in which a rotor must read a speed for its dead readings to be
#: filled from the others (`fill_dead_rotor`), s: its ratio to them is a median over it.
MIN_LIVE_TIME = 1.0


def fill_dead_rotor(t: np.ndarray, n: np.ndarray, dead: np.ndarray, airborne: np.ndarray,
                    source: str) -> tuple[np.ndarray, str | None]:
    """One rotor's dead readings (0 while the vehicle flies) taken from the other rotors.

    When every dead sample is one rotor w reading 0, and w reads a speed for at least
    `MIN_LIVE_TIME` of the flight at flying thrust, its speed in the dead samples is r × the
    others' RMS speed, r the median of its ratio to them where it reads: the vehicle kept
    flying, so the channel, not the motor, is dead. The fill carries w's share of the
    thrust but none of its differential (roll, pitch and yaw) information; the note says
    so. Otherwise nothing is filled (the samples are left out as gaps).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s.
    n : ndarray, shape (N, k)
        Rotor speeds, rad/s.
    dead : ndarray of bool, shape (N,)
        `dead_rotor_samples`.
    airborne : ndarray of bool, shape (N,)
        Samples at flying thrust.
    source : str
        The file, for the note.

    Returns
    -------
    n : ndarray, shape (N, k)
        The speeds, filled (a copy) or as given.
    note : str or None
        What was filled; None when nothing was.
    """
    if not dead.any() or n.shape[1] < 3:
        return n, None
    zero = n[dead] == 0.0
    rotors = np.flatnonzero(zero.any(axis=0))
    if rotors.size != 1 or not zero[:, rotors[0]].all():
        return n, None
    w = int(rotors[0])
    others = np.sqrt(np.mean(np.delete(n, w, axis=1) ** 2, axis=1))
    live = airborne & ~dead & (n[:, w] > 0.0) & (others > 0.0)
    period = float(np.median(np.diff(t))) if t.size > 1 else np.inf
    if live.sum() < 2 or live.sum() * period < MIN_LIVE_TIME:
        return n, None
    ratio = float(np.median(n[live, w] / others[live]))
    filled = n.copy()
    filled[dead, w] = ratio * others[dead]
    return filled, (
        f"{source}: rotor {w + 1} reads 0 while the others fly in "
        f"{_plural(int(dead.sum()), 'sample')} (first at t = {t[int(np.argmax(dead))]:.3f} s) "
        "and the vehicle keeps flying: a dead reading; its speed there is taken as "
        f"{ratio:.3g} × the others' RMS speed (its median ratio to them where it reads), which "
        "carries its thrust but not its share of the roll, pitch and yaw information")


def drop_unphysical_samples(t: np.ndarray, stacked: np.ndarray, source: str,
                            vehicle: VehicleConfig, min_run: float
                            ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Leave out a frozen pose and stuck or dead rotors (module docstring) as gaps.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing sample times, s.
    stacked : ndarray, shape (N, 7 + k)
        Position (m), quaternion, rotor speeds (rad/s), columns side by side.
    source : str
        The file, for messages.
    vehicle : VehicleConfig
        Nominal c_T and mass (what is flying thrust).
    min_run : float
        Shortest frozen pose or dead rotor run left out, s (the longest gap bridged).

    Returns
    -------
    t, stacked : ndarray
        Without the samples left out.
    notes : list of str
        One line per kind of sample left out.

    Raises
    ------
    LogFormatError
        Less than `MIN_DURATION` is left.
    """
    n = stacked[:, 7:]
    with np.errstate(over="ignore", invalid="ignore"):
        thrust = collective_thrust(vehicle.parameters.c_T, n)
        # A dead rotor lowers Σ c_T n²; the median rotor tells whether the others fly.
        typical = n.shape[1] * np.median(rotor_thrust(vehicle.parameters.c_T, n), axis=1)
    weight = FLYING_THRUST * vehicle.mass * GRAVITY
    airborne = thrust >= weight
    found = [
        (frozen_samples(t, stacked[:, :3], airborne, min_run)
         | frozen_samples(t, stacked[:, 3:7], airborne, min_run),
         "the pose repeats one value exactly in {count} (first at t = {first:.3f} s), in runs "
         f"longer than {min_run:g} s: a frozen pose source"),
        (_stuck_rotor_samples(t, n, airborne, min_run),
         "the rotor speeds repeat one value exactly in {count} (first at t = {first:.3f} s), "
         f"in flight runs longer than {min_run:g} s: a stuck reading"),
    ]
    dead = dead_rotor_samples(t, n, typical >= weight, min_run)
    filled, note = fill_dead_rotor(t, n, dead, airborne, source)
    if note is not None:
        stacked = stacked.copy()
        stacked[:, 7:] = filled
        dead = np.zeros_like(dead)
    found.append((dead, "a rotor reads 0 while the others fly in {count} (first at t = "
                  f"{{first:.3f}} s), in runs longer than {min_run:g} s: a dead reading or a "
                  "stopped motor"))
    drop = np.zeros(t.shape[0], dtype=bool)
    notes = [] if note is None else [note]
    for flagged, what in found:
        if flagged.any():
            detail = what.format(count=_plural(int(flagged.sum()), "sample"),
                                 first=t[int(np.argmax(flagged))])
            notes.append(f"{source}: {detail}; those samples are left out as gaps")
            drop |= flagged
    if drop.any() and ((~drop).sum() < 2 or np.ptp(t[~drop]) < MIN_DURATION):
        raise LogFormatError(f"{'; '.join(notes)}, and too little is left "
                             f"({MIN_DURATION:g} s needed)")
    return t[~drop], stacked[~drop], notes


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
    # interpolated with a modelled error (`mavsysid.estimation.flight`).
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
    logged_t, logged_rotors = t, stacked[:, 7:7 + k]
    t, stacked, more = drop_unphysical_samples(t, stacked, source, vehicle, MAX_GAP)
    notes += more
    # A dead channel filled: the series as logged no longer says what the rows do, so the
    # rows become the inputs (else its zeros would come back where the inputs are read).
    filled = not np.array_equal(logged_rotors[np.isin(logged_t, t)], stacked[:, 7:7 + k])
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
    inputs = InputSamples(((t, stacked[:, 7:7 + k]),)) if filled else data.inputs
    repaired = dataclasses.replace(data, t=t, position=stacked[:, :3], quaternion=q,
                                   rotor_speeds=stacked[:, 7:7 + k], inputs=inputs,
                                   warnings=(*data.warnings, *notes), segment_starts=starts)
    _check_hover(repaired, vehicle)
    return repaired


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
    imu : Imu or None
        The IMU (body FLU), not yet cleaned; None when the log has none.
    rotor_scale_sigma : float
        Relative 1σ of the rotor speeds' scale (`mavsysid.estimation.flight.FlightData`).
    """

    source: str
    pose: Series | None
    pose_source: PoseSource
    rotors: tuple[Series, ...]
    warnings: tuple[str, ...] = ()
    truth: dict | None = None
    pose_hint: str = ""
    control_spans: tuple[tuple[float, float], ...] | None = None
    imu: Imu | None = None
    rotor_scale_sigma: float = 0.0


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
    imu, more = clean_imu(streams.imu, t, values[:, 3:7], source)
    data = FlightData(t=t, position=values[:, :3], quaternion=values[:, 3:7],
                      rotor_speeds=speeds, source=source,
                      pose_source=streams.pose_source,
                      truth=streams.truth, warnings=(*notes, *more),
                      inputs=InputSamples(tuple(columns)), imu=imu,
                      rotor_scale_sigma=streams.rotor_scale_sigma)
    return validate_flight(data, vehicle, np.vstack(gaps))


#: Median specific force over a flight an accelerometer in m/s² reads (g while hovering,
#: more in manoeuvres): outside this range it reads another unit (g, mG) or is broken.
ACCEL_MEDIAN_RANGE = (0.5 * GRAVITY, 2.0 * GRAVITY)
#: The gyro's rates against the attitude's: a gain outside this range is another unit
#: (deg/s reads 57×) or frame (FRD read as FLU turns the y and z gains negative).
GYRO_GAIN_RANGE = (0.7, 1.4)
#: The gyro's rotation over `_GYRO_CHECK_WINDOW` against the attitude's (RMS ratio) above
#: which it is another unit, whatever their correlation.
GYRO_SIZE_MAX = 2.0
#: Attitude rates (RMS, rad/s) and their correlation with the gyro below which the gain
#: is not judged (a flight that hardly turns, or a pose too noisy to tell), over windows
#: of this many seconds (long enough that the attitude's noise does not matter).
_GYRO_CHECK_RATE, _GYRO_CHECK_CORRELATION, _GYRO_CHECK_WINDOW = 0.1, 0.8, 0.2


def _clean_sensor(series: ImuSeries | None, t: np.ndarray, source: str
                  ) -> tuple[ImuSeries | None, list[str]]:
    """A sensor's samples repaired and kept within the pose's span (one sample either
    side), or None with a note when fewer than two remain.

    A sample repeating the one before it exactly on all three axes is left out: a sensor's
    noise never repeats to the last bit, so it is a held reading (an IMU slower than the
    pose, written on every pose row) or a stuck one, not a new measurement at its time.
    """
    if series is None:
        return None, []
    values = np.asarray(series.values, dtype=float)
    held = np.concatenate([[False], np.all(values[1:] == values[:-1], axis=1)])
    notes = []
    if held.any():
        notes.append(f"{source}: dropped {_plural(int(held.sum()), 'sample')} of {series.label} "
                     "repeating the previous one exactly (a held or stuck reading)")
    ts, vs, more = repair_samples(np.asarray(series.t, dtype=float)[~held], values[~held],
                                  source, series.label)
    notes += more
    inside = _inside(ts, (float(t[0]), float(t[-1])), margin=1)
    ts, vs = ts[inside], vs[inside]
    if ts.shape[0] < 2:
        return None, [*notes, f"{source}: {series.label} has no samples during the flight; "
                      "not used"]
    return dataclasses.replace(series, t=ts, values=vs), notes


def _rotations(t: np.ndarray, q: np.ndarray, gyro: ImuSeries
               ) -> tuple[np.ndarray, np.ndarray]:
    """Body rotations over windows of about `_GYRO_CHECK_WINDOW` s: from the attitude, and
    the gyro's integral over the same window, each (M, 3) rad."""
    step = max(1, round(_GYRO_CHECK_WINDOW / float(np.median(np.diff(t)))))
    i = np.arange(0, t.shape[0] - step, step)
    attitude = quat_log(quat_multiply(quat_conjugate(q[i]), q[i + step]))
    cumulative = np.concatenate([[np.zeros(3)], np.cumsum(
        0.5 * (gyro.values[1:] + gyro.values[:-1]) * np.diff(gyro.t)[:, None], axis=0)])
    integral = np.column_stack([np.interp(t[i + step], gyro.t, cumulative[:, a])
                                - np.interp(t[i], gyro.t, cumulative[:, a]) for a in range(3)])
    return attitude, integral


def _check_gyro(gyro: ImuSeries, t: np.ndarray, q: np.ndarray, source: str) -> None:
    """Refuse a gyro whose rates are not the attitude's (another unit or frame): over
    windows of a fraction of a second the gyro's integral is the attitude's rotation."""
    if t[-1] - t[0] < 4.0 * _GYRO_CHECK_WINDOW:
        return
    attitude, integral = _rotations(t, q, gyro)
    for axis, name in enumerate("xyz"):
        ref, got = attitude[:, axis], integral[:, axis]
        power = float(ref @ ref)
        if np.sqrt(power / ref.size) < _GYRO_CHECK_RATE * _GYRO_CHECK_WINDOW:
            continue
        corr = float(ref @ got) / np.sqrt(power * float(got @ got) + 1e-300)
        gain = float(ref @ got) / power
        if abs(corr) >= _GYRO_CHECK_CORRELATION and not (
                GYRO_GAIN_RANGE[0] <= gain <= GYRO_GAIN_RANGE[1]):
            raise LogFormatError(
                f"{source}: {gyro.label} about {name} reads {gain:.3g} × the rate of the "
                "logged attitude (expected about 1): not rad/s in the body frame FLU (deg/s "
                "reads 57 ×, a frame mix-up −1)")
        # Rates too large to be the attitude's, correlated or not (deg/s wrapped in an
        # int16 field correlates with nothing).
        size = np.sqrt(float(got @ got) / power)
        if size > GYRO_SIZE_MAX:
            raise LogFormatError(
                f"{source}: {gyro.label} about {name} reads rates {size:.3g} × as large as "
                "the logged attitude's (RMS): not rad/s (deg/s reads 57 ×)")


def clean_imu(imu: Imu | None, t: np.ndarray, q: np.ndarray, source: str
              ) -> tuple[Imu | None, list[str]]:
    """The IMU repaired, kept within the pose's span and checked against the pose.

    Rows with NaN dropped and times put in order (`repair_samples`, with notes); a sensor
    with no sample in the flight is left out with a note.

    Parameters
    ----------
    imu : Imu or None
        As read, body FLU.
    t : ndarray, shape (N,)
        The pose's times, s.
    q : ndarray, shape (N, 4)
        The pose's attitude, body → world.
    source : str
        The log, named in notes and refusals.

    Returns
    -------
    imu : Imu or None
        None when neither sensor remains.
    notes : list of str

    Raises
    ------
    LogFormatError
        An accelerometer whose median specific force is outside `ACCEL_MEDIAN_RANGE`, or a
        gyro whose rates are not the attitude's (`GYRO_GAIN_RANGE`): another unit or frame.
    """
    if imu is None:
        return None, []
    gyro, notes = _clean_sensor(imu.gyro, t, source)
    accel, more = _clean_sensor(imu.accel, t, source)
    notes += more
    if accel is not None:
        median = float(np.median(np.linalg.norm(accel.values, axis=1)))
        if not ACCEL_MEDIAN_RANGE[0] <= median <= ACCEL_MEDIAN_RANGE[1]:
            raise LogFormatError(
                f"{source}: {accel.label} reads a median specific force of {median:.3g} m/s² "
                f"over the flight (a flying vehicle: about {GRAVITY:g}): not m/s²")
    if gyro is not None:
        _check_gyro(gyro, t, q, source)
    if gyro is None and accel is None:
        return None, notes
    return dataclasses.replace(imu, gyro=gyro, accel=accel), notes
