"""A segment against an autopilot's kinematic envelope (``mavsysid plan --autopilot-limits``).

The position controller that flies the plan follows only so much speed, acceleration,
jerk, lean angle and yaw rate (`mavsysid.vehicle.kinematic_limits.KinematicLimits`, set
from the autopilot's parameters). The planner keeps each segment's sampled peaks below
`PLAN_SHARE` of every limit: the streamer's pre-flight check samples the whole flight at
other instants (`mavsysid.vehicle.kinematic_limits.kinematic_peaks`), and a sampled
polynomial peak is within a relative (ω Δt)²/8 of the true one, far below the share left.
"""

from __future__ import annotations

import numpy as np
from mavsysid.planner.segments import Segment
from mavsysid.planner.unit_interval import POWERS
from mavsysid.vehicle.kinematic_limits import (
    PEAK_STEP,
    KinematicLimits,
    KinematicPeaks,
    exceeded,
    flat_peaks,
)
from mavsysid.vehicle.trajectory import FlatOutputs

from mavsysid.errors import InputError

__all__ = ["PLAN_SHARE", "check_limits", "exceeded_limits", "segment_peaks"]

#: Share of each autopilot limit a plan may use.
PLAN_SHARE = 0.98


def segment_peaks(segment: Segment, step: float = PEAK_STEP) -> KinematicPeaks:
    """The kinematic peaks of ``segment``, sampled every ``step`` s and at both ends."""
    n = max(2, int(np.ceil(segment.duration / step)) + 1)
    s = np.linspace(0.0, 1.0, n)
    v = (s[:, None] ** POWERS) @ segment.derivative_coeffs
    flat = FlatOutputs(position=v[:, 0:3], velocity=v[:, 3:6], acceleration=v[:, 6:9],
                       jerk=v[:, 9:12], snap=v[:, 12:15], yaw=v[:, 15],
                       yaw_rate=v[:, 16], yaw_acceleration=v[:, 17])
    return flat_peaks(flat)


def exceeded_limits(segment: Segment, limits: KinematicLimits) -> str:
    """The first quantity of ``limits`` whose `PLAN_SHARE` the segment's peaks exceed, or ""."""
    share = KinematicLimits(**{name: None if limit is None else PLAN_SHARE * limit
                               for name, limit in vars(limits).items()})
    over = exceeded(segment_peaks(segment), share)
    return over[0][0] if over else ""


def check_limits(limits: KinematicLimits) -> None:
    """Refuse a limit that is not a positive finite number.

    Raises
    ------
    InputError
        One line naming the quantity (``--autopilot-limits``).
    """
    for name, value in vars(limits).items():
        if value is not None and not (np.isfinite(value) and value > 0.0):
            raise InputError(f"--autopilot-limits: {name} {value:g}: expected a limit > 0 "
                             "(a parameter of 0 or below that means 'no limit' is left out)")
