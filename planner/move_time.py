"""How long a move takes within an autopilot's kinematic limits: the duration sampler's
guide when the limits are tight (``plan --autopilot-limits``).

The paper samples a segment's duration from T ∈ [d / v_max, T_max] (`segments.duration_range`).
Under an autopilot's envelope most of that interval is too fast: ArduCopter's stock limits
(2.5 m/s² horizontal, 1 m/s² vertical, 5 m/s³ jerk, 60°/s yaw) need 3.2 s for a 2 m move
at rest at both ends in the planner's own polynomial, more than quad_x's T_max of 3 s, so
most sampled connections fail the limit check and the graph grows too slowly to reach a
flight that fills the budget in the planning time.

A segment at rest at both ends is one unit polynomial stretched in space and time, so its
peaks scale as d/T, d/T², d/T³ (yaw: Δψ/T, Δψ/T²): `rest_to_rest_time` gives, in closed
form, the shortest T at which such a segment keeps every limit. A segment between moving
states is not at rest, so this is a guide for sampling, not a bound: the search samples
from T ≥ that time, up to `MOVE_TIME_STRETCH` times it when that is longer than T_max
(`move_duration_range`), and the refinement keeps segments as short (`longest_segment`).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
from mavsysid.planner.kinematic_check import PLAN_SHARE, segment_peaks
from mavsysid.planner.segments import VertexState, connect_fixed, duration_range
from mavsysid.vehicle.config import Limits
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.kinematic_limits import KinematicLimits, KinematicPeaks

__all__ = ["MOVE_TIME_STRETCH", "longest_segment", "move_duration_range", "rest_to_rest_time"]

#: Under an autopilot's limits a segment lasts at least its move's rest-to-rest time and
#: up to this many times it, when that is longer than the vehicle's
#: `Limits.segment_time_max`. Without it, ArduCopter's stock limits admitted 0.4 % of the
#: sampled connections and the first flight to fill a 20 s budget came after 4–7 s of CPU;
#: with it, after 0.5–0.6 s (quad_x, seeds 1–3). Against 2, or the lower end left at
#: d / v_max: docs/benchmarks.md, "Filling the budget within an autopilot's limits".
MOVE_TIME_STRETCH = 1.5


@cache
def _unit_peaks() -> KinematicPeaks:
    """Peaks of the planner's rest-to-rest segment over 1 m along x and 1 rad of yaw in 1 s."""
    start = VertexState.hover(np.zeros(3), 0.0)
    end = VertexState.hover(np.array([1.0, 0.0, 0.0]), 1.0)
    return segment_peaks(connect_fixed(start, end, 1.0))


def _time_for(distance: float, unit_peak: float, limit: float | None, order: int) -> float:
    """Shortest T with distance · unit_peak / T^order ≤ limit (0 when unlimited or still)."""
    if limit is None or distance <= 0.0:
        return 0.0
    return float((distance * unit_peak / limit) ** (1.0 / order))


def rest_to_rest_time(displacement: np.ndarray, yaw_change: float,
                      limits: KinematicLimits) -> float:
    """Shortest duration of a rest-to-rest segment of the planner within ``limits``.

    Each limit is used at `mavsysid.planner.kinematic_check.PLAN_SHARE`, as the planner's
    limit check does; the lean angle bounds the horizontal acceleration by g tan(tilt).

    Parameters
    ----------
    displacement : ndarray, shape (3,)
        End minus start position, m, world ENU.
    yaw_change : float
        End minus start yaw, rad.
    limits : KinematicLimits
        The autopilot's envelope, SI (None: unlimited).

    Returns
    -------
    float
        T in s (0 for no move, or no limit on it).
    """
    unit = _unit_peaks()
    share = {name: None if value is None else PLAN_SHARE * value
             for name, value in vars(limits).items()}
    horizontal = math.hypot(float(displacement[0]), float(displacement[1]))
    vertical = float(displacement[2])
    rise = abs(vertical)
    # Speed, acceleration and jerk of the path scale as its length; the unit segment's
    # horizontal peaks are those of a 1 m path.
    v1, a1, j1 = unit.speed_xy, unit.accel_xy, unit.jerk_xy
    lean = share["tilt"]
    vertical_accels = [a for a in (share["accel_up"], share["accel_down"]) if a is not None]
    times = [
        _time_for(horizontal, v1, share["speed_xy"], 1),
        _time_for(horizontal, a1, share["accel_xy"], 2),
        _time_for(horizontal, a1, None if lean is None else GRAVITY * math.tan(lean), 2),
        _time_for(horizontal, j1, share["jerk_xy"], 3),
        _time_for(rise, v1, share["climb"] if vertical > 0.0 else share["descent"], 1),
        # A rest-to-rest move speeds up and slows down: both vertical accelerations occur.
        _time_for(rise, a1, min(vertical_accels) if vertical_accels else None, 2),
        _time_for(rise, j1, share["jerk_z"], 3),
        _time_for(math.hypot(horizontal, rise), j1, share["jerk"], 3),
        _time_for(abs(yaw_change), unit.yaw_rate, share["yaw_rate"], 1),
        _time_for(abs(yaw_change), unit.yaw_acceleration, share["yaw_acceleration"], 2),
    ]
    return max(times)


def _move_time(a: VertexState, b_position: np.ndarray, b_yaw: float,
               autopilot: KinematicLimits | None) -> float:
    if autopilot is None:
        return 0.0
    return rest_to_rest_time(b_position - a.position[0], b_yaw - float(a.yaw[0]), autopilot)


def longest_segment(a: VertexState, b_position: np.ndarray, b_yaw: float, limits: Limits,
                    autopilot: KinematicLimits | None) -> float:
    """The longest a segment from ``a`` to (``b_position``, ``b_yaw``) may last, s:
    ``limits.segment_time_max``, or `MOVE_TIME_STRETCH` times the move's rest-to-rest time
    within ``autopilot`` (None: no autopilot limits) when that is longer.

    Parameters
    ----------
    a : VertexState
        Start of the segment.
    b_position : ndarray, shape (3,)
        End position, m, world ENU.
    b_yaw : float
        End yaw, rad (on the branch the segment turns to).
    limits : Limits
        The vehicle's (its ``segment_time_max``, s, is used).
    autopilot : KinematicLimits or None
        The autopilot's envelope (None: ``limits.segment_time_max`` alone).
    """
    move = _move_time(a, b_position, b_yaw, autopilot)
    return max(limits.segment_time_max, MOVE_TIME_STRETCH * move)


def move_duration_range(a: VertexState, b_position: np.ndarray, b_yaw: float,
                        budget_left: float, limits: Limits,
                        autopilot: KinematicLimits | None) -> tuple[float, float] | None:
    """Interval to sample the duration of a segment a → (``b_position``, ``b_yaw``) from.

    The paper's [d / v_max, min(budget left, T_max)] (`segments.duration_range`); under an
    autopilot's limits, no shorter than the move's rest-to-rest time t within them, and up
    to `MOVE_TIME_STRETCH` t when that exceeds T_max.

    Parameters
    ----------
    a : VertexState
        Start of the segment.
    b_position : ndarray, shape (3,)
        End position, m.
    b_yaw : float
        End yaw, rad (on the branch the segment turns to).
    budget_left : float
        Flight time still available at ``a``, s.
    limits : Limits
        The vehicle's (``speed_max``, ``segment_time_max``).
    autopilot : KinematicLimits or None
        The autopilot's envelope (None: the paper's interval).

    Returns
    -------
    tuple of float or None
        ``(lo, hi)`` in s, or None when the interval is empty.
    """
    move = _move_time(a, b_position, b_yaw, autopilot)
    return duration_range(float(np.linalg.norm(b_position - a.position[0])), limits.speed_max,
                          budget_left, max(limits.segment_time_max, MOVE_TIME_STRETCH * move),
                          min_duration=move)
