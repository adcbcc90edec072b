"""Re-planning in flight, offline: an opening flight, an estimate, the rest planned from it.

A plan robust to the prior (docs/evaluation.md):

1. plan a short **opening** (budget `OPENING_BUDGET`) from the prior, with the prior's wide
   belief, so that the planner's chance-constrained rotor check keeps it gentle (in the box
   inset by the rotor clearance, so that its end is a valid start: `opening_settings`);
2. fly it (here in the offline simulator, `mavsysid.flight.offline.simulator`) and estimate
   θ̂ and its covariance Σ as ``mavsysid estimate`` does (`mavsysid.estimation.estimate`, the same
   pipeline a ``stream --replan-budget`` run uses: robust start, filter, batch
   refinement, σ aware of residual whiteness, and the checks that refuse);
   when ``estimate`` refuses it (the model cannot follow the opening: a diverged filter,
   a force balance that contradicts θ̂), the rest is planned from the belief the opening
   was planned from (`belief_after_opening`): as gentle as the opening, which flew;
   otherwise the rest is planned for the noise the opening's filter met (its pose σ and
   rate, the unmodelled force and moment it fitted: `mavsysid.pipeline.plan.for_noise_met`),
   a parameter answered at or below 0 at the prior's value and σ
   (`mavsysid.pipeline.replanned_stream.positive_belief`);
3. plan the **rest** of the budget with θ̂ as the config's θ and Σ relative to θ̂
   (Σ_ij / (θ̂_i θ̂_j)) as ``PlannerSettings.prior_covariance``, starting at the hover where
   the opening ended;
4. the opening and the rest, back to back, are one continuous flight (`concatenate`).

Offline, the vehicle does not fly on while the rest is planned: the reported flight is the
whole trajectory flown again from the start with the same seed, as ``stream`` would fly
it in one run (the opening's noise realisation is the same, since the seed is).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mavsysid.estimation import (
    ParameterEstimate,
    estimate,
    load_flight,
)
from mavsysid.flight.offline.simulator import Simulator
from mavsysid.pipeline.plan import for_noise_met
from mavsysid.pipeline.replanned_stream import (
    opening_belief,
    positive_belief,
    prior_estimate,
    relative_covariance,
)
from mavsysid.planner.plan_request import rotor_clearance
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.robust_plan import plan_most_confident
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["CONTINUITY_TOLERANCE", "OPENING_BUDGET", "START_MARGIN", "ReplannedFlight",
           "concatenate", "end_hover", "opening_settings", "replan_flight", "rest_settings"]

#: Default budget of the opening flight, s.
OPENING_BUDGET = 6.0
#: Largest jump of any flat output (position, yaw and their derivatives, SI) allowed
#: where two trajectories are joined.
CONTINUITY_TOLERANCE = 1e-6
#: How much farther inside the box than the rotor clearance the opening stays, m.
START_MARGIN = 0.01


@dataclass(frozen=True)
class ReplannedFlight:
    """A flight planned in two parts, the second from what the first taught.

    Attributes
    ----------
    trajectory : PiecewisePolynomial
        The opening then the rest: one flight, from rest to rest.
    opening, rest : PlanResult
        The two plans.
    posterior : ParameterEstimate
        θ̂ and Σ (SI) estimated from the opening (`mavsysid.estimation.estimate`), or the
        prior belief when that estimate was refused.
    rest_config : VehicleConfig
        The prior vehicle with θ̂: the model the rest was planned with.
    rest_settings : PlannerSettings
        The settings the rest was planned with.
    refusal : str or None
        Why the opening's estimate was refused (the rest was then planned from the prior
        belief); None when it was accepted.
    """

    trajectory: PiecewisePolynomial
    opening: PlanResult
    rest: PlanResult
    posterior: ParameterEstimate
    rest_config: VehicleConfig
    rest_settings: PlannerSettings
    refusal: str | None = None


def end_hover(trajectory: PiecewisePolynomial) -> tuple[float, float, float, float]:
    """(x, y, z, yaw) at the end of ``trajectory`` (m, rad), where it hovers."""
    flat = trajectory.flat_outputs(np.array([trajectory.duration]))
    x, y, z = (float(v) for v in flat.position[0])
    return x, y, z, float(flat.yaw[0])


def _padded(coeffs: np.ndarray, n: int) -> np.ndarray:
    """Coefficients (…, m) padded with zero high powers to (…, n): the same polynomial."""
    pad = [(0, 0)] * (coeffs.ndim - 1) + [(0, n - coeffs.shape[-1])]
    return np.pad(coeffs, pad)


def concatenate(first: PiecewisePolynomial, second: PiecewisePolynomial,
                tolerance: float = CONTINUITY_TOLERANCE) -> PiecewisePolynomial:
    """``second`` flown right after ``first``: one trajectory.

    Raises
    ------
    ValueError
        The flat outputs (position to snap, yaw to yaw acceleration) jump by more than
        ``tolerance`` at the join: ``second`` does not start where ``first`` ends.
    """
    end = first.flat_outputs(np.array([first.duration]))
    start = second.flat_outputs(np.array([0.0]))
    jump = max(float(np.max(np.abs(np.asarray(getattr(end, name))
                                   - np.asarray(getattr(start, name)))))
               for name in ("position", "velocity", "acceleration", "jerk", "snap", "yaw",
                            "yaw_rate", "yaw_acceleration"))
    if jump > tolerance:
        raise ValueError(f"the trajectories do not join: a flat output jumps by {jump:.3g}")
    n_pos = max(first.position_coeffs.shape[-1], second.position_coeffs.shape[-1])
    n_yaw = max(first.yaw_coeffs.shape[-1], second.yaw_coeffs.shape[-1])
    return PiecewisePolynomial(
        np.concatenate([first.durations, second.durations]),
        np.concatenate([_padded(first.position_coeffs, n_pos),
                        _padded(second.position_coeffs, n_pos)]),
        np.concatenate([_padded(first.yaw_coeffs, n_yaw), _padded(second.yaw_coeffs, n_yaw)]))


def opening_settings(settings: PlannerSettings, config: VehicleConfig,
                     budget: float) -> PlannerSettings:
    """The opening's settings: ``budget`` long, in the box inset by the rotor clearance.

    The planner keeps the centre of gravity in its box, but a start hover must keep the
    rotors in it too (`mavsysid.planner.plan_request`); inset, the opening ends where the
    rest may start.
    """
    box = np.asarray(settings.box, dtype=float)
    inset = rotor_clearance(config) + START_MARGIN
    inner = np.concatenate([box[:3] + inset, box[3:] - inset])
    return replace(settings, budget=budget, box=tuple(float(v) for v in inner))


def rest_settings(settings: PlannerSettings, posterior: ParameterEstimate,
                  opening: PiecewisePolynomial) -> PlannerSettings:
    """The settings for the rest: what is left of the budget, from the opening's end hover,
    with the posterior's covariance relative to θ̂ as the prior."""
    return replace(settings, budget=settings.budget - opening.duration,
                   start=end_hover(opening), prior_covariance=relative_covariance(posterior))


def replan_flight(prior: VehicleConfig, settings: PlannerSettings, simulator: Simulator,
                  directory: Path, opening_budget: float = OPENING_BUDGET) -> ReplannedFlight:
    """Plan an opening, fly and filter it, plan the rest from the posterior; join them.

    Parameters
    ----------
    prior : VehicleConfig
        The vehicle as known before flying (its θ is the prior mean).
    settings : PlannerSettings
        The whole flight's settings (budget, box, planning time per plan, seed, prior σ).
    simulator : Simulator
        Flies the opening (the true vehicle).
    directory : Path
        Flight directory of the opening (pose.csv, truth.csv, meta.json).
    opening_budget : float
        Budget of the opening, s; must leave some of ``settings.budget``.

    Raises
    ------
    JobFailedError
        A plan cannot be found, or the opening's estimate cannot seed a re-plan.
    """
    if not 0.0 < opening_budget < settings.budget:
        raise ValueError(f"opening budget {opening_budget:g} s: expected within "
                         f"(0, {settings.budget:g}) s")
    # Each part at the most confident chance-constrained rotor check that admits a flight:
    # with the wide prior that is usually a low z (a gentle opening), after it a high one.
    opening = plan_most_confident(prior, opening_settings(settings, prior, opening_budget)).result
    simulator.run(opening.trajectory, directory)
    # The estimate the stream's continuation would use (pipeline.replanned_stream).
    before = prior_estimate(prior, settings)
    posterior, noise, refusal = opening_belief(
        lambda: estimate(load_flight(directory / "pose.csv", prior), prior), before)
    posterior, _ = positive_belief(posterior, before)
    config = prior.with_parameters(posterior.value)
    model, later = for_noise_met(config, rest_settings(settings, posterior, opening.trajectory),
                                 noise)
    confident = plan_most_confident(model, later)
    rest, later = confident.result, replace(later, rotor_confidence=confident.rotor_confidence)
    return ReplannedFlight(concatenate(opening.trajectory, rest.trajectory), opening, rest,
                           posterior, config, later, refusal)
