"""Kinematic peaks of a trajectory and an autopilot's kinematic envelope, in SI.

A position controller (ArduPilot's, PX4's) limits what it follows by speed,
acceleration, jerk, lean angle and yaw rate. `KinematicLimits` is that envelope in SI
(None: no limit), `kinematic_peaks` the largest values a trajectory asks for, and
`exceeded` compares the two. The lean angle a flat trajectory implies is the angle of its
thrust direction a + g ẑ from the vertical (ENU, z up), stated once in `tilt_angle`.
The planner keeps its segments inside such an envelope; the streamer checks a plan
against the limits the autopilot reports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.trajectory import FlatOutputs, Trajectory

__all__ = ["KINEMATIC_FIELDS", "PEAK_STEP", "KinematicLimits", "KinematicPeaks", "exceeded",
           "flat_peaks", "kinematic_peaks", "tilt_angle"]

#: Sampling step of `kinematic_peaks`, s (polynomial peaks are flat: the sampled maximum
#: is within a relative (ω Δt)²/8 of the true one).
PEAK_STEP = 0.005


@dataclass(frozen=True)
class KinematicPeaks:
    """Largest kinematic values of a trajectory (SI, world ENU).

    Attributes
    ----------
    speed_xy, climb, descent : float
        Horizontal speed, upward and downward vertical speed, m/s (≥ 0).
    accel_xy, accel_up, accel_down : float
        Horizontal acceleration, upward and downward vertical acceleration, m/s² (≥ 0).
    jerk_xy, jerk_z, jerk : float
        Horizontal, vertical and total jerk, m/s³.
    tilt : float
        Lean angle of the thrust direction from the vertical, rad.
    yaw_rate, yaw_acceleration : float
        |ψ̇| rad/s, |ψ̈| rad/s².
    """

    speed_xy: float = 0.0
    climb: float = 0.0
    descent: float = 0.0
    accel_xy: float = 0.0
    accel_up: float = 0.0
    accel_down: float = 0.0
    jerk_xy: float = 0.0
    jerk_z: float = 0.0
    jerk: float = 0.0
    tilt: float = 0.0
    yaw_rate: float = 0.0
    yaw_acceleration: float = 0.0


#: The quantities of `KinematicPeaks` / `KinematicLimits`, in their order.
KINEMATIC_FIELDS = tuple(f.name for f in fields(KinematicPeaks))


@dataclass(frozen=True)
class KinematicLimits:
    """A kinematic envelope: the same quantities as `KinematicPeaks`, None = no limit."""

    speed_xy: float | None = None
    climb: float | None = None
    descent: float | None = None
    accel_xy: float | None = None
    accel_up: float | None = None
    accel_down: float | None = None
    jerk_xy: float | None = None
    jerk_z: float | None = None
    jerk: float | None = None
    tilt: float | None = None
    yaw_rate: float | None = None
    yaw_acceleration: float | None = None

    def is_empty(self) -> bool:
        """Whether no quantity is limited."""
        return all(getattr(self, name) is None for name in KINEMATIC_FIELDS)


def tilt_angle(acceleration: np.ndarray) -> np.ndarray:
    """Lean angle of the thrust direction a + g ẑ from the vertical, rad.

    Parameters
    ----------
    acceleration : ndarray, shape (S, 3)
        Acceleration, m/s², world ENU (z up).

    Returns
    -------
    ndarray, shape (S,)
        In [0, π]; above π/2 the thrust would have to point down.
    """
    a = np.asarray(acceleration, dtype=float)
    return np.arctan2(np.linalg.norm(a[:, :2], axis=1), a[:, 2] + GRAVITY)


def flat_peaks(flat: FlatOutputs) -> KinematicPeaks:
    """The largest kinematic values over samples of flat outputs (see `KinematicPeaks`)."""
    v, a, j = flat.velocity, flat.acceleration, flat.jerk

    def top(x: np.ndarray) -> float:
        return float(np.max(x)) if x.size else 0.0

    return KinematicPeaks(
        speed_xy=top(np.linalg.norm(v[:, :2], axis=1)), climb=max(top(v[:, 2]), 0.0),
        descent=max(top(-v[:, 2]), 0.0), accel_xy=top(np.linalg.norm(a[:, :2], axis=1)),
        accel_up=max(top(a[:, 2]), 0.0), accel_down=max(top(-a[:, 2]), 0.0),
        jerk_xy=top(np.linalg.norm(j[:, :2], axis=1)), jerk_z=top(np.abs(j[:, 2])),
        jerk=top(np.linalg.norm(j, axis=1)), tilt=top(tilt_angle(a)),
        yaw_rate=top(np.abs(flat.yaw_rate)), yaw_acceleration=top(np.abs(flat.yaw_acceleration)))


def kinematic_peaks(trajectory: Trajectory, step: float = PEAK_STEP) -> KinematicPeaks:
    """The largest kinematic values of ``trajectory``, sampled every ``step`` s (and at
    its end)."""
    duration = float(trajectory.duration)
    n = max(2, math.ceil(duration / step) + 1)
    return flat_peaks(trajectory.flat_outputs(np.linspace(0.0, duration, n)))


def exceeded(peaks: KinematicPeaks, limits: KinematicLimits
             ) -> list[tuple[str, float, float]]:
    """(quantity, peak, limit) for every quantity whose peak is above its limit."""
    out = []
    for name in KINEMATIC_FIELDS:
        limit = getattr(limits, name)
        if limit is not None and getattr(peaks, name) > limit:
            out.append((name, getattr(peaks, name), limit))
    return out
