"""A flight's fresh pose samples on a uniform grid, with the rotor speeds at any delay.

Real logs repeat the pose: a logger running faster than the on-board estimator writes
the last estimate again (a Crazyflie's 500 Hz uSD log repeats about half its rows), and
a lost radio packet repeats a row. A repeated pose is not a measurement of the vehicle
at the row's time but of an earlier one; taken at face value it makes the position a
staircase whose second derivative is noise. So a row whose position and attitude both
equal the previous row's exactly is left out of the pose (`fresh_pose`), and the fresh
samples are interpolated onto a uniform grid at the log's median step (linear in position
and in the sign-continuous quaternion, renormalised). A simulated or motion-capture pose
never repeats to the last bit in flight, so nothing is left out there.

The rotor speeds keep every row: they are their own measurement. `UniformSegment.rotor_speeds`
interpolates them at t − δ, for a pose that lags the rotor speeds by δ
(`mavsysid.estimation.time_offset`). A flight with gaps (`FlightData.segment_starts`)
gives one `UniformSegment` per segment long enough to use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.vehicle.rotation import continuous_sign

__all__ = ["UniformSegment", "fresh_pose", "uniform_segments"]


def fresh_pose(position: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """Rows whose pose differs from the previous row's, shape (N,) bool.

    Parameters
    ----------
    position : ndarray, shape (N, 3)
        m.
    quaternion : ndarray, shape (N, 4)
        Unit, [w, x, y, z].

    Returns
    -------
    ndarray of bool, shape (N,)
        True for the first row and every row not repeating its predecessor exactly.
    """
    pose = np.hstack([np.asarray(position, float), np.asarray(quaternion, float)])
    repeat = np.all(np.diff(pose, axis=0) == 0.0, axis=1)
    return np.concatenate([[True], ~repeat])


def _interp_columns(t_new: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t_new, t, x[:, j]) for j in range(x.shape[1])])


@dataclass(frozen=True)
class UniformSegment:
    """One contiguous stretch of a flight on a uniform grid (M samples).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Grid times, s, uniform step ``dt``.
    dt : float
        Grid step, s.
    position : ndarray, shape (M, 3)
        m, world ENU, interpolated from the fresh pose samples.
    quaternion : ndarray, shape (M, 4)
        Unit, body → world, sign-continuous.
    rotor_time : ndarray, shape (K,)
        Times of the logged rotor speeds, s.
    rotor_samples : ndarray, shape (K, k)
        Logged rotor speeds, rad/s.
    fresh_fraction : float
        Fraction of the segment's rows whose pose was fresh.
    """

    t: np.ndarray
    dt: float
    position: np.ndarray
    quaternion: np.ndarray
    rotor_time: np.ndarray
    rotor_samples: np.ndarray
    fresh_fraction: float

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def rotor_speeds(self, delay: float = 0.0) -> np.ndarray:
        """Rotor speeds at t − ``delay`` on the grid, shape (M, k), rad/s.

        Parameters
        ----------
        delay : float
            s by which the pose lags the rotor speeds (held at the ends).
        """
        return _interp_columns(self.t - delay, self.rotor_time, self.rotor_samples)


def _segment(t: np.ndarray, position: np.ndarray, quaternion: np.ndarray,
             rotors: np.ndarray, dt: float) -> UniformSegment | None:
    fresh = fresh_pose(position, quaternion)
    tf = t[fresh]
    if tf.size < 4:
        return None
    grid = tf[0] + dt * np.arange(int(np.floor((tf[-1] - tf[0]) / dt)) + 1)
    p = _interp_columns(grid, tf, position[fresh])
    q = _interp_columns(grid, tf, continuous_sign(quaternion[fresh]))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return UniformSegment(grid, dt, p, q, np.asarray(t, float), np.asarray(rotors, float),
                          float(fresh.mean()))


def uniform_segments(flight: FlightData, min_duration: float) -> list[UniformSegment]:
    """Each segment of ``flight`` spanning at least ``min_duration`` s, on a uniform grid.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds at the pose times.
    min_duration : float
        Shortest segment kept, s.

    Returns
    -------
    list of UniformSegment
        In time order; the grid step is the median sample interval of the whole flight.
    """
    t = np.asarray(flight.t, float)
    if t.size < 2:
        return []
    dt = float(np.median(np.diff(t)))
    out = []
    for start, stop in flight.segment_bounds:
        if stop - start < 4 or t[stop - 1] - t[start] < min_duration:
            continue
        seg = _segment(t[start:stop], flight.position[start:stop],
                       flight.quaternion[start:stop], flight.rotor_speeds[start:stop], dt)
        if seg is not None and seg.t[-1] - seg.t[0] >= min_duration:
            out.append(seg)
    return out
