"""Baselines a reviewer accepts, for the same vehicle, budget and limits as the planner.

Each baseline gives a trajectory within the planner's budget and box:

* ``"random"``: the paper's random baseline (`mavsysid.planner.baseline.plan_random`);
* ``"practitioner"``: the built-in Lissajous excitation with yaw
  (`mavsysid.flight.offline.excitation`), sped up or slowed down **once**, by bisection on
  one time scale k (every frequency × k), to the fastest version that passes the planner's
  own segment check at the prior θ: box, thrust, speed, yaw acceleration, body rate, rotor
  speeds (and the autopilot's envelope when the settings carry one). A practitioner tunes
  one knob; the figure's shape stays the built-in one;
* ``"oracle"``: the D-optimal planner given the true θ as its prior mean;
* ``"paper_constraints"``: the D-optimal planner with the paper's constraint set, that is
  without the rotor-speed check (``PlannerSettings.rotor_check = False``), an ablation.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.planner.baseline import plan_random
from mavsysid.planner.feasibility import check_segment
from mavsysid.planner.kinematic_check import exceeded_limits
from mavsysid.planner.rrbt import plan
from mavsysid.planner.segments import Segment
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError

__all__ = ["BASELINES", "ScaledExcitation", "baseline_trajectory", "excitation_spec",
           "excitation_violation", "oracle_plan", "paper_constraint_plan",
           "practitioner_excitation", "trajectory_segments"]

#: Baseline kinds, compared with the D-optimal planner ("dopt").
BASELINES: tuple[str, ...] = ("random", "practitioner", "oracle", "paper_constraints")
#: Time scales the bisection brackets: slowest tried first, fastest a bound.
SCALE_RANGE = (0.05, 8.0)
#: Bisection steps on the time scale (relative bracket 2⁻¹⁴ of the range).
BISECTION_STEPS = 14


@dataclass(frozen=True)
class ScaledExcitation:
    """The practitioner's excitation after scaling.

    Attributes
    ----------
    trajectory : PiecewisePolynomial
        The flight, budget long, starting and ending at rest.
    scale : float
        Time scale k applied to every frequency of the built-in figure (1: as built in).
    spec : ExcitationSpec
        The figure flown.
    binding : str
        The constraint the next faster scale violates (`mavsysid.planner.feasibility.
        CONSTRAINTS`, or ``"autopilot:<peak>"``); "" if the fastest scale passed.
    """

    trajectory: PiecewisePolynomial
    scale: float
    spec: ExcitationSpec
    binding: str


def trajectory_segments(trajectory: PiecewisePolynomial) -> list[Segment]:
    """The pieces of a trajectory as planner segments (position N = 10, yaw N = 6)."""
    return [Segment(float(d), trajectory.position_coeffs[i], trajectory.yaw_coeffs[i])
            for i, d in enumerate(trajectory.durations)]


def excitation_spec(settings: PlannerSettings, scale: float) -> ExcitationSpec:
    """The built-in figure at time scale ``scale``, budget long, centred in the box.

    Knots are spaced 1/scale of the built-in spacing, so that each piece spans the same
    phase of the figure at any speed.
    """
    base = ExcitationSpec()
    box = np.asarray(settings.box, dtype=float)
    centre = 0.5 * (box[:3] + box[3:])
    return replace(base, duration=float(settings.budget),
                   center=(float(centre[0]), float(centre[1]), float(centre[2])),
                   frequency=tuple(float(f * scale) for f in base.frequency),
                   yaw_frequency=base.yaw_frequency * scale,
                   knot_spacing=base.knot_spacing / scale)


def excitation_violation(trajectory: PiecewisePolynomial, prior: VehicleConfig,
                         settings: PlannerSettings) -> str:
    """The first limit a trajectory breaks under the planner's check at the prior, or "".

    The same check as every planned segment (`mavsysid.planner.graph_search.GraphSearch.
    feasible`): vehicle limits at the prior θ with the settings' rotor headroom and rotor
    check, then the autopilot's envelope if given.
    """
    box = np.asarray(settings.box, dtype=float)
    for segment in trajectory_segments(trajectory):
        result = check_segment(segment, prior, box, rotor_headroom=settings.rotor_headroom,
                               rotor_check=settings.rotor_check)
        if not result.feasible:
            return result.reason
        if settings.autopilot_limits is not None:
            peak = exceeded_limits(segment, settings.autopilot_limits)
            if peak:
                return f"autopilot:{peak}"
    return ""


def practitioner_excitation(prior: VehicleConfig, settings: PlannerSettings
                            ) -> ScaledExcitation:
    """The built-in excitation scaled once to the planner's limits at the prior.

    Bisection on the time scale k in `SCALE_RANGE` for the fastest figure that passes
    `excitation_violation` (aggressiveness grows with k: accelerations as k², jerk as k³).

    Raises
    ------
    JobFailedError
        Not even the slowest scale fits (the figure leaves the box, or hover breaks a limit).
    """
    lo, hi = SCALE_RANGE
    low_traj = excitation_trajectory(excitation_spec(settings, lo))
    reason = excitation_violation(low_traj, prior, settings)
    if reason:
        raise JobFailedError(f"the built-in excitation breaks the {reason} limit even at "
                             f"time scale {lo:g}")
    fast = excitation_trajectory(excitation_spec(settings, hi))
    binding = excitation_violation(fast, prior, settings)
    if not binding:
        return ScaledExcitation(fast, hi, excitation_spec(settings, hi), "")
    for _ in range(BISECTION_STEPS):
        mid = np.sqrt(lo * hi)  # geometric: the bracket spans two decades
        trajectory = excitation_trajectory(excitation_spec(settings, mid))
        reason = excitation_violation(trajectory, prior, settings)
        if reason:
            hi, binding = mid, reason
        else:
            lo, low_traj = mid, trajectory
    return ScaledExcitation(low_traj, float(lo), excitation_spec(settings, lo), binding)


def oracle_plan(truth: VehicleConfig, settings: PlannerSettings) -> PiecewisePolynomial:
    """The D-optimal planner given the true θ as its prior mean (an upper reference)."""
    return plan(truth, settings).trajectory


def paper_constraint_plan(prior: VehicleConfig, settings: PlannerSettings
                          ) -> PiecewisePolynomial:
    """The D-optimal planner with the paper's constraint set: no rotor-speed check."""
    return plan(prior, replace(settings, rotor_check=False)).trajectory


def baseline_trajectory(kind: str, prior: VehicleConfig, truth: VehicleConfig,
                        settings: PlannerSettings) -> PiecewisePolynomial:
    """The trajectory of baseline ``kind`` (one of `BASELINES`) for the same budget and box.

    ``prior`` is the model the practitioner and the planners know; ``truth`` is used only by
    the oracle.
    """
    if kind == "random":
        return plan_random(prior, settings).trajectory
    if kind == "practitioner":
        return practitioner_excitation(prior, settings).trajectory
    if kind == "oracle":
        return oracle_plan(truth, settings)
    if kind == "paper_constraints":
        return paper_constraint_plan(prior, settings)
    raise ValueError(f"unknown baseline {kind!r}: expected one of {', '.join(BASELINES)}")
