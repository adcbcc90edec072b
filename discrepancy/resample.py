"""A flight put on a uniform time grid for the diagnosis smoother.

The Savitzky–Golay smoother of `mavsysid.discrepancy.residuals` needs uniform samples;
autopilot logs and real motion-capture logs jitter and drop samples. `resample_flight`
puts a flight on a grid at its median sample interval: position by a cubic spline,
attitude by slerp (`mavsysid.vehicle.rotation.interpolate_quaternions`), rotor
speeds linearly. An interval longer than `MAX_INTERPOLATED` median intervals, or between
two of the reader's segments (`FlightData.segment_starts`), is a *gap*:
nothing is interpolated across it (the grid samples inside hold a straight line only so
that the arrays stay uniform) and the residual leaves it out, with one smoother edge on
each side, as it does at the flight's ends (`Resampling.usable`).

What resampling does to the statistics of the diagnosis. An interpolated sample is a
weighted sum of its logged neighbours, so the measurement noise of neighbouring grid
samples is correlated and its variance varies along the grid. The diagnosis' noise
statistics count one *effective* sample per correlation length of the smoothed residual
(`mavsysid.discrepancy.regression`, Ljung–Box on samples that far apart in
`mavsysid.discrepancy.residual_stats`). Smoothing spreads a sample over one window
(w grid samples); interpolation adds the reach of the interpolant: ``support − 1`` more
(`INTERPOLATION_SUPPORT`, the cubic spline's, whose weights fall by ≈ 4 per knot). So
`Resampling.block` = w + support − 1 for a resampled flight and exactly w for a uniform
one. Resampling creates no information: the grid holds about as many samples as the log
(median rate), and dropped samples interpolated over short holes add none — the residual
variance is estimated from the data, so their larger noise enters the fit, not the count.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
from mavsysid.estimation import (
    MAX_JITTER,
    FlightData,
    uniform_step,
)
from mavsysid.vehicle.rotation import continuous_sign, interpolate_quaternions
from scipy.interpolate import CubicSpline
from scipy.ndimage import binary_dilation

from mavsysid.errors import InputError

__all__ = [
    "DIAGNOSIS_RATE",
    "INTERPOLATION_SUPPORT",
    "MAX_INTERPOLATED",
    "MAX_JITTER",
    "Resampling",
    "average_blocks",
    "resample_flight",
    "uniform_step",
]

#: Longest interval interpolated across, in median sample intervals (up to three dropped
#: samples); a longer one is a gap.
MAX_INTERPOLATED = 4.0

#: Logged samples an interpolated grid sample effectively depends on (cubic spline).
INTERPOLATION_SUPPORT = 4

#: Rate the diagnosis works at, Hz: a faster log is averaged down to it (`average_blocks`).
#: The residual is smoothed over 0.6 s and carries the rotors' effect up to ≈ 2 Hz; an
#: average over m samples (10 ms at 500 Hz) passes 2 Hz to within 0.07 % and keeps the
#: noise information (its variance falls by m), while the smoother's cost falls by m².
DIAGNOSIS_RATE = 100.0


@dataclass(frozen=True)
class Resampling:
    """How a flight was put on its uniform grid.

    Attributes
    ----------
    dt : float
        Grid step, s (the log's median sample interval).
    valid : ndarray of bool, shape (N,)
        Grid samples outside the gaps.
    gaps : tuple of (float, float)
        Start and end (s) of the intervals not interpolated across.
    support : int
        Logged samples a grid sample depends on: 1 when the log was used as it is.
    spread : tuple of (float, float)
        Shortest and longest logged interval outside the gaps, in units of ``dt``.
    averaged : int
        Grid samples of the uniform log averaged into one (`average_blocks`), 1: none.
    """

    dt: float
    valid: np.ndarray
    gaps: tuple[tuple[float, float], ...] = ()
    support: int = 1
    spread: tuple[float, float] = (1.0, 1.0)
    averaged: int = 1

    @property
    def log_dt(self) -> float:
        """The log's own sample interval, s: how finely it stamps pose and rotor speeds."""
        return self.dt / self.averaged

    @property
    def resampled(self) -> bool:
        """True when the grid samples were interpolated."""
        return self.support > 1

    def block(self, window: int) -> int:
        """Correlation length of a residual smoothed over ``window`` grid samples, samples."""
        return window + self.support - 1

    def usable(self, edge: int) -> np.ndarray:
        """Grid samples at least ``edge`` samples away from every gap, bool (N,)."""
        if self.valid.all():
            return self.valid.copy()
        return ~binary_dilation(~self.valid, iterations=max(int(edge), 1))

    def describe(self) -> str:
        """One line for the report: what was done to the log."""
        lo, hi = self.spread
        if self.support == 1:
            return (f"pose log averaged over blocks of {self.averaged} samples, to "
                    f"{1.0 / self.dt:.4g} Hz")
        text = (f"pose log resampled to a uniform {1.0 / self.log_dt:.4g} Hz (its sample "
                f"intervals were {lo:.2f}–{hi:.2f} × the median, short dropouts included)")
        if self.averaged > 1:
            text += f", then averaged over blocks of {self.averaged} samples"
        if self.gaps:
            total = sum(b - a for a, b in self.gaps)
            text += (f"; {len(self.gaps)} gap(s) of more than {MAX_INTERPOLATED:g} samples "
                     f"({total:.2f} s in all) left out of the residual")
        return text


def resample_flight(flight: FlightData) -> tuple[FlightData, Resampling]:
    """The flight on a uniform grid at its median rate, and how it got there.

    A log whose intervals are all within `MAX_JITTER` of the median is returned as it is.

    Parameters
    ----------
    flight : FlightData

    Returns
    -------
    flight : FlightData
        On the grid t₀ + k dt (a new object only when resampled).
    resampling : Resampling
    """
    t = np.asarray(flight.t, float)
    if len(t) < 2:
        raise InputError(f"{flight.source}: {len(t)} pose sample(s): nothing to diagnose")
    intervals = np.diff(t)
    step = float(np.median(intervals))
    if not step > 0.0 or np.any(intervals <= 0.0):
        raise InputError(f"{flight.source}: pose time stamps are not strictly increasing")
    deviation = np.abs(intervals - step) / step
    if np.max(deviation) <= MAX_JITTER and len(flight.segment_starts) == 1:
        spread = (float(np.min(intervals)) / step, float(np.max(intervals)) / step)
        return flight, Resampling(step, np.ones(len(t), bool), spread=spread)
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1)
    is_gap = intervals > MAX_INTERPOLATED * step
    # The reader's segments (`FlightData.segment_starts`) are never bridged either.
    is_gap[[s - 1 for s in flight.segment_starts if s > 0]] = True
    gaps = tuple((float(t[i]), float(t[i + 1])) for i in np.flatnonzero(is_gap))
    valid = np.ones(grid.size, bool)
    for a, b in gaps:
        valid &= ~((grid > a) & (grid < b))
    position = _position_on_grid(t, np.asarray(flight.position, float), grid, is_gap)
    quaternion = interpolate_quaternions(t, np.asarray(flight.quaternion, float), grid)
    speeds = np.asarray(flight.rotor_speeds, float)
    rotor_speeds = np.column_stack([np.interp(grid, t, speeds[:, i])
                                    for i in range(speeds.shape[1])])
    bridged = intervals[~is_gap] / step
    spread = (float(bridged.min()), float(bridged.max())) if bridged.size else (1.0, 1.0)
    resampled = _on_grid(flight, grid, position, quaternion, rotor_speeds)
    return resampled, Resampling(step, valid, gaps, INTERPOLATION_SUPPORT, spread)


def _on_grid(flight: FlightData, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray,
            rotor_speeds: np.ndarray) -> FlightData:
    """The flight with its samples replaced by ones on a uniform grid.

    What the grid does not touch is kept: the logged rotor-speed samples, the IMU at its
    own rates, the rotor speeds' scale uncertainty, the reader's notes. The grid is one
    segment: its gaps are `Resampling.valid`'s, not the reader's segments.
    """
    return replace(flight, t=t, position=position, quaternion=quaternion,
                   rotor_speeds=rotor_speeds, segment_starts=(0,))


def _position_on_grid(t: np.ndarray, position: np.ndarray, grid: np.ndarray,
                      is_gap: np.ndarray) -> np.ndarray:
    """Cubic spline within each run of samples between gaps, a straight line across gaps.

    The spline's error is O(dt⁴ p⁗), far below motion-capture noise, where linear
    interpolation would leave a bias of a dt²/8 correlated with the acceleration the
    diagnosis measures. Across a gap a spline could overshoot without bound; the line
    stays between its ends (those samples are left out of the residual anyway).
    """
    out = np.column_stack([np.interp(grid, t, position[:, i]) for i in range(3)])
    bounds = np.concatenate([[0], np.flatnonzero(is_gap) + 1, [len(t)]])
    for lo, hi in itertools.pairwise(bounds):
        if hi - lo < 4:
            continue  # too few samples for a spline: the line stays
        inside = (grid >= t[lo]) & (grid <= t[hi - 1])
        out[inside] = CubicSpline(t[lo:hi], position[lo:hi], axis=0)(grid[inside])
    return out


def average_blocks(flight: FlightData, resampling: Resampling,
                   rate: float = DIAGNOSIS_RATE) -> tuple[FlightData, Resampling]:
    """A uniformly sampled flight faster than ``rate`` averaged over blocks of m samples.

    m = ⌊(1/dt) / rate⌋; at m = 1 the flight is returned as it is. Time, position, rotor
    speeds and the sign-continuous quaternion (renormalised) are each the mean over the
    block; a block touching a gap is invalid. Disjoint blocks keep the noise of
    neighbouring samples independent (an interpolated log's correlation reaches at most
    into the next block: support 2).

    Parameters
    ----------
    flight : FlightData
        On a uniform grid (`resample_flight`).
    resampling : Resampling
        How it got there.
    rate : float
        Target rate, Hz.

    Returns
    -------
    flight : FlightData
    resampling : Resampling
        With ``dt`` the block's, ``averaged`` = m.
    """
    m = int(np.floor(1.0 / (resampling.dt * rate) + 1e-9))
    if m <= 1:
        return flight, resampling
    n = len(flight.t) // m

    def mean(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)[:n * m]
        return x.reshape(n, m, *x.shape[1:]).mean(axis=1)

    q = mean(continuous_sign(flight.quaternion))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    valid = resampling.valid[:n * m].reshape(n, m).all(axis=1)
    averaged = _on_grid(flight, mean(flight.t), mean(flight.position), q,
                       mean(flight.rotor_speeds))
    return averaged, replace(resampling, dt=resampling.dt * m, valid=valid,
                             support=min(resampling.support, 2), averaged=m)
