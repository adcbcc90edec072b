"""A segment against an autopilot's kinematic envelope (``mavsysid plan --autopilot-limits``).

The position controller that flies the plan follows only so much speed, acceleration,
jerk, lean angle and yaw rate (`mavsysid.vehicle.kinematic_limits.KinematicLimits`, set
from the autopilot's parameters). The planner keeps each segment's exact peaks below
`PLAN_SHARE` of every limit; the streamer's pre-flight check finds the same exact peaks over
the whole flight (`mavsysid.vehicle.kinematic_limits.kinematic_peaks`), so the share left
is a margin for the autopilot, not for sampling.
"""

from __future__ import annotations

import numpy as np
from mavsysid.planner.segments import Segment
from mavsysid.vehicle.kinematic_limits import (
    KINEMATIC_FIELDS,
    KinematicLimits,
    KinematicPeaks,
    exceeded,
    polynomial_peaks,
)

from mavsysid.errors import InputError

__all__ = ["PLAN_SHARE", "check_limits", "exceeded_limits", "segment_peaks"]

#: Share of each autopilot limit a plan may use.
PLAN_SHARE = 0.98


def segment_peaks(segment: Segment) -> KinematicPeaks:
    """The exact kinematic peaks of ``segment`` (`kinematic_limits.polynomial_peaks`)."""
    return polynomial_peaks(segment.position_coeffs[None], segment.yaw_coeffs[None],
                            np.array([segment.duration]))


def exceeded_limits(segment: Segment, limits: KinematicLimits) -> str:
    """A quantity of ``limits`` whose `PLAN_SHARE` the segment's exact peaks exceed, or "".

    The first such quantity on a grid of samples when there is one, else the first at the
    exact peaks.
    """
    share = KinematicLimits(**{name: None if limit is None else PLAN_SHARE * limit
                               for name, limit in vars(limits).items()})
    limited = tuple(name for name in KINEMATIC_FIELDS if getattr(share, name) is not None)
    args = (segment.position_coeffs[None], segment.yaw_coeffs[None],
            np.array([segment.duration]))
    # Grid peaks are below the exact ones: one over its share there is over it exactly,
    # without the roots, which cost most of the time.
    over = exceeded(polynomial_peaks(*args, limited, exact=False), share)
    if not over:
        over = exceeded(polynomial_peaks(*args, limited), share)
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
