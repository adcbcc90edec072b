"""Kinematic peaks of a trajectory and an autopilot's kinematic envelope, in SI.

A position controller (ArduPilot's, PX4's) limits what it follows by speed,
acceleration, jerk, lean angle and yaw rate. `KinematicLimits` is that envelope in SI
(None: no limit), `kinematic_peaks` the largest values a trajectory asks for (exact: at
the roots of polynomial derivatives, `mavsysid.vehicle.polynomial_extremes`), and
`exceeded` compares the two. The lean angle a flat trajectory implies is the angle of its
thrust direction a + g ẑ from the vertical (ENU, z up), stated once in
`mavsysid.vehicle.polynomial_extremes.tilt_angle`.
The planner keeps its segments inside such an envelope; the streamer checks a plan
against the limits the autopilot reports.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from mavsysid.vehicle.polynomial_extremes import segment_extremes
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["KINEMATIC_FIELDS", "KINEMATIC_WORDS", "KinematicLimits", "KinematicPeaks", "exceeded",
           "kinematic_peaks", "polynomial_peaks"]


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
#: Each quantity in words, for messages.
KINEMATIC_WORDS = {
    "speed_xy": "horizontal speed", "climb": "climb rate", "descent": "descent rate",
    "accel_xy": "horizontal acceleration", "accel_up": "upward acceleration",
    "accel_down": "downward acceleration", "jerk_xy": "horizontal jerk",
    "jerk_z": "vertical jerk", "jerk": "jerk", "tilt": "lean angle",
    "yaw_rate": "yaw rate", "yaw_acceleration": "yaw acceleration"}
#: Each peak as (quantity of `segment_extremes`, sign): climb/descent and the vertical
#: accelerations are the two signs of one signed quantity.
_EXTREME_OF = {name: (name, 1.0) for name in KINEMATIC_FIELDS} | {
    "climb": ("vertical_speed", 1.0), "descent": ("vertical_speed", -1.0),
    "accel_up": ("vertical_accel", 1.0), "accel_down": ("vertical_accel", -1.0)}


@dataclass(frozen=True)
class KinematicLimits:
    """A kinematic envelope: the same quantities as `KinematicPeaks`, None = no limit.

    Attributes
    ----------
    speed_xy, climb, descent : float or None
        Horizontal, upward and downward speed, m/s.
    accel_xy, accel_up, accel_down : float or None
        Horizontal, upward and downward acceleration, m/s².
    jerk_xy, jerk_z, jerk : float or None
        Horizontal, vertical and total jerk, m/s³.
    tilt : float or None
        Lean angle, rad.
    yaw_rate, yaw_acceleration : float or None
        rad/s, rad/s².
    """

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


def polynomial_peaks(position_coeffs: np.ndarray, yaw_coeffs: np.ndarray,
                     durations: np.ndarray, fields: tuple[str, ...] = KINEMATIC_FIELDS,
                     exact: bool = True) -> KinematicPeaks:
    """The exact largest kinematic values of polynomial segments (see `KinematicPeaks`).

    Parameters
    ----------
    position_coeffs : ndarray, shape (M, 3, N)
        Per segment and axis (ENU, z up), coefficients of increasing powers of the
        segment's local time τ, m/s^k.
    yaw_coeffs : ndarray, shape (M, Ny)
        Per segment, yaw coefficients of increasing powers of τ, rad/s^k.
    durations : ndarray, shape (M,)
        Segment durations, s.
    fields : tuple of str
        The peaks wanted (of `KINEMATIC_FIELDS`); the others are left 0.
    exact : bool
        False: only the grid of `segment_extremes`, peaks that may be low (a quick
        rejection test: a grid peak over a limit is over it).

    Returns
    -------
    KinematicPeaks
        Each the maximum over all segments, at the exact extremes
        (`mavsysid.vehicle.polynomial_extremes.segment_extremes`).
    """
    names = tuple(dict.fromkeys(_EXTREME_OF[f][0] for f in fields))
    top = dict.fromkeys(KINEMATIC_FIELDS, 0.0)
    for pc, yc, duration in zip(position_coeffs, yaw_coeffs, durations, strict=True):
        ext = segment_extremes(pc, yc, float(duration), names, exact=exact)
        for f in fields:
            name, sign = _EXTREME_OF[f]
            top[f] = max(top[f], float(np.max(sign * ext[name][1])))
    return KinematicPeaks(**top)


def kinematic_peaks(trajectory: PiecewisePolynomial) -> KinematicPeaks:
    """The exact largest kinematic values of ``trajectory`` (`polynomial_peaks`).

    Parameters
    ----------
    trajectory : PiecewisePolynomial
        The flight.
    """
    return polynomial_peaks(trajectory.position_coeffs, trajectory.yaw_coeffs,
                            trajectory.durations)


def exceeded(peaks: KinematicPeaks, limits: KinematicLimits
             ) -> list[tuple[str, float, float]]:
    """(quantity, peak, limit) for every quantity whose peak is above its limit.

    Parameters
    ----------
    peaks : KinematicPeaks
        A trajectory's peaks.
    limits : KinematicLimits
        The envelope.
    """
    out = []
    for name in KINEMATIC_FIELDS:
        limit = getattr(limits, name)
        if limit is not None and getattr(peaks, name) > limit:
            out.append((name, getattr(peaks, name), limit))
    return out
