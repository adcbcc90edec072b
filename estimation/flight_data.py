"""A flight as the estimator sees it: timed pose measurements and rotor speeds.

Every log reader (`mavsysid.estimation.readers.load_flight`) returns a `FlightData`, whatever the
file format; frames are already converted to ENU/FLU and units to SI.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

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
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray
    source: str
    pose_source: Literal["motion_capture", "autopilot"] = "motion_capture"
    truth: dict | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)

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

    def time_slice(self, t0: float, t1: float) -> FlightData:
        """The samples with t0 ≤ t ≤ t1."""
        keep = (self.t >= t0) & (self.t <= t1)
        return FlightData(self.t[keep], self.position[keep], self.quaternion[keep],
                          self.rotor_speeds[keep], self.source, self.pose_source,
                          self.truth, self.warnings)
