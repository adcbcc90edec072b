"""Samples no working sensor produces in flight: a frozen pose, a stuck or dead rotor.

A measured position, attitude or set of rotor speeds never repeats to the last bit while the
vehicle flies, and a rotor that reads 0 while the others carry the vehicle has a dead channel. Such
samples come from a stalled estimator, a lost motion-capture body, a dead ESC telemetry
channel or a logger repeating its last value; the filter would take them for a vehicle
that stopped dead, or for a rotor that carries no thrust. They are left out as gaps
(`drop_unphysical_samples`, called by `mavsysid.estimation.readers.checks.validate_flight`),
with one note each; one rotor's dead readings, while the vehicle keeps flying and the rotor
reads elsewhere, are filled from the other rotors instead (`fill_dead_rotor`). On the
ground (a noise-free simulation, a pre-arm estimator, idling rotors) a signal may well
stand still, so only runs mostly at flying thrust count.
"""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.flight_data import MIN_DURATION
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import collective_thrust, rotor_thrust

from mavsysid.errors import LogFormatError

__all__ = [
    "FLYING_THRUST",
    "MAX_BODY_RATE",
    "MIN_LIVE_TIME",
    "attitude_jumps",
    "dead_rotor_samples",
    "drop_unphysical_samples",
    "fill_dead_rotor",
    "frozen_samples",
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
