"""A flight as the estimator sees it: timed pose measurements and rotor speeds.

Every log reader (`mavsysid.estimation.readers.load_flight`) returns a `FlightData`, whatever the
file format; frames are already converted to ENU/FLU and units to SI.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from mavsysid.estimation.input_noise import InputSamples

__all__ = ["MIN_DURATION", "POSE_SOURCES", "FlightData"]

#: Shortest flight worth estimating from, s: the log checks and the estimator both refuse
#: less.
MIN_DURATION = 2.0

#: Where the pose came from: raw motion capture, or the autopilot's own (filtered,
#: lagged) estimator, which calls for a larger measurement noise.
POSE_SOURCES = ("motion_capture", "autopilot")


@dataclass(frozen=True)
class FlightData:
    """Samples of one flight, N of them.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time, s, strictly increasing.
    position : ndarray, shape (N, 3)
        Measured position, m, world ENU.
    quaternion : ndarray, shape (N, 4)
        Measured attitude, unit ``[w, x, y, z]``, body FLU → world ENU.
    rotor_speeds : ndarray, shape (N, k)
        Actual rotor speeds, rad/s, in the vehicle config's rotor order.
    source : str
        The file it was read from (with ``+ pose FILE`` when merged).
    pose_source : {"motion_capture", "autopilot"}
        Origin of the pose measurements.
    truth : dict or None
        The ``truth`` block of a simulated flight's meta.json (true parameters under
        ``"parameters"``), if any. Never used by estimation, only for reporting errors.
    warnings : tuple of str
        Problems found and repaired while reading (NaN rows dropped, …), one line each.
    segment_starts : tuple of int
        Index of the first sample of each contiguous segment, increasing, starting with 0:
        a gap too long to bridge separates two segments (see
        `mavsysid.estimation.readers.checks`). One segment, ``(0,)``, by default.
    inputs : InputSamples or None
        The rotor-speed samples as logged, before interpolation to ``t``: the filter adds
        the interpolation error as process noise (`mavsysid.estimation.input_noise`).
        None: the rotor speeds are exact at ``t`` (as in a pose log).
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray
    source: str
    pose_source: Literal["motion_capture", "autopilot"] = "motion_capture"
    truth: dict | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)
    segment_starts: tuple[int, ...] = (0,)
    inputs: InputSamples | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time span of the samples, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    @property
    def rotor_count(self) -> int:
        """k, the number of rotor-speed columns."""
        return int(self.rotor_speeds.shape[1])

    @property
    def true_theta(self) -> np.ndarray | None:
        """True θ (6,) when the flight was simulated, else None."""
        if not self.truth or "parameters" not in self.truth:
            return None
        p = self.truth["parameters"]
        return np.array([p["c_T"], p["c_D"], p["c_M"], p["j_x"], p["j_y"], p["j_z"]], float)

    @property
    def segment_bounds(self) -> list[tuple[int, int]]:
        """``(start, stop)`` sample indices of each segment (``stop`` exclusive)."""
        ends = (*self.segment_starts[1:], len(self))
        return list(zip(self.segment_starts, ends, strict=True))

    def segment(self, index: int) -> FlightData:
        """Segment ``index`` alone, as a one-segment flight."""
        start, stop = self.segment_bounds[index]
        return FlightData(self.t[start:stop], self.position[start:stop],
                          self.quaternion[start:stop], self.rotor_speeds[start:stop],
                          self.source, self.pose_source, self.truth, self.warnings,
                          inputs=self.inputs)

    def longest_segment(self) -> int:
        """Index of the segment spanning the most time (the first of equals)."""
        spans = [self.t[stop - 1] - self.t[start] for start, stop in self.segment_bounds]
        return int(np.argmax(spans))

    def time_slice(self, t0: float, t1: float) -> FlightData:
        """The samples with t0 ≤ t ≤ t1 (segments kept where they start inside)."""
        keep = (self.t >= t0) & (self.t <= t1)
        # One contiguous time range: a segment start cut off lies before t0 or after t1.
        index = np.cumsum(keep) - 1
        starts = sorted({0, *(int(index[s]) for s in self.segment_starts if keep[s])})
        return FlightData(self.t[keep], self.position[keep], self.quaternion[keep],
                          self.rotor_speeds[keep], self.source, self.pose_source,
                          self.truth, self.warnings, tuple(starts), inputs=self.inputs)
