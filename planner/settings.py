"""What the planner takes: its settings (`PlannerSettings`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.vehicle.autopilot_loop import AutopilotLoop
from mavsysid.vehicle.kinematic_limits import KinematicLimits

__all__ = ["PlannerSettings"]


@dataclass(frozen=True)
class PlannerSettings:
    """Inputs of a planning run.

    Attributes
    ----------
    budget : float
        Longest flight, s, including the final stopping segment.
    planning_time : float
        Wall-clock planning time, s (the planner stops at whichever of this and
        ``max_samples`` comes first). The graph search gets the first
        1 − ``refine_share`` of it, more (up to half of it) while its best flight uses
        less than 90 % of the budget.
    max_samples : int or None
        Sample budget: with it (and an unlimited planning time) the result depends only
        on the seed, not on the machine or its load.
    box : tuple of 6 float
        Flight volume [x_min, y_min, z_min, x_max, y_max, z_max], m, world ENU.
    start : tuple of 4 float or None
        Start hover [x, y, z, yaw] (m, rad); the box centre with yaw 0 by default.
    seed : int
        Seed of the sampler.
    measurement_rate : float
        Pose measurement rate the estimator will see, Hz. The chosen flight's predicted σ
        is propagated at exactly this rate.
    propagation_rate : float
        Step rate of belief propagation during the search, Hz; each step carries the
        information of measurement_rate / propagation_rate measurements (at 25 Hz for
        100 Hz measurements the predicted σ differ by < 0.1 %, at a quarter of the cost).
    prior_relative_sigma : float
        Prior σ of each parameter relative to the config's nominal θ.
    refine_share : float
        Share of the planning time spent refining the search's best flight
        (`mavsysid.planner.refine`); the graph search gets the rest.
    refine_steps : int
        Most refinement steps (0: no refinement). With a sample budget this, not the
        clock, ends the refinement, so the result still depends only on the seed. The
        default is above what 21 s of refinement reach (≈ 30 000 steps on a loaded
        2-core machine), so with a planning time the clock ends it; with a sample budget
        it takes a few minutes.
    refine_split : int
        Pieces each segment of the search's best flight is cut into before refinement
        (1: none). The flight stays the same; the refinement gets more, shorter segments
        to shape (faster manoeuvres), which lowered the D-optimality it reaches by 5–15 %
        at 2–3 pieces in bench trials.
    rotor_headroom : float
        Fraction of the rotor n² range (`Limits.rotor_speed_min` to `rotor_speed_max`)
        the plan leaves free at each end, for the autopilot's feedback and for a true
        vehicle whose θ differs from the planner's
        (`mavsysid.planner.feasibility.rotor_square_range`).
    autopilot_limits : KinematicLimits or None
        The envelope of the autopilot that will fly the plan (``plan --autopilot-limits``):
        every segment keeps its peaks inside it (`mavsysid.planner.kinematic_check`);
        None: the vehicle's own limits only.
    prior_covariance : tuple of 6 tuples of 6 float, or None
        Prior covariance of θ relative to the config's θ (of δθ_j/θ_j, with correlations):
        the planner's initial θ belief and the spread the rotor check allows for. None:
        diag(prior_relative_sigma²). A re-planned flight passes the posterior of its
        opening flight here.
    rotor_confidence : float
        One-sided normal quantile z of the chance-constrained rotor check
        (`mavsysid.planner.feasibility.check_segment`): each rotor slab must hold at
        v(θ̂) ± z σ_v, σ_v the first-order spread of the slab value under
        ``prior_covariance``. 0 (the default) checks at the prior θ only; 1.645 is 95 % per
        slab and sample. With the default ±50 % prior hardly any flight passes at 1.645
        (a firefly plan found none in 1.5 s of search): a prior that wide is narrowed by
        an opening flight first (`mavsysid.experiments.replanned_flight`).
    rotor_check : bool
        Check rotor speeds (through the allocation at the prior θ). False gives the paper's
        constraint set (thrust, body rate, yaw acceleration, box, speed; no rotor check),
        the ablation of `mavsysid.experiments.baselines`.
    autopilot : AutopilotLoop or None
        The closed loop of the autopilot that will fly the plan
        (`mavsysid.vehicle.autopilot_loop`): the information and the rotor check are
        computed on the flight it is predicted to fly from the streamed setpoints (each
        segment from steady flight on its start during the search; the chosen flight's σ
        over time on the whole flight). None: the setpoints are flown exactly (the
        paper's assumption, the flatness map).
    """

    budget: float = 30.0
    planning_time: float = 30.0
    max_samples: int | None = None
    box: tuple[float, float, float, float, float, float] = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)
    start: tuple[float, float, float, float] | None = None
    seed: int = 0
    measurement_rate: float = 100.0
    propagation_rate: float = 25.0
    prior_relative_sigma: float = 0.5
    refine_share: float = 0.9
    refine_steps: int = 100_000
    refine_split: int = 2
    rotor_headroom: float = 0.0
    autopilot_limits: KinematicLimits | None = None
    rotor_check: bool = True
    prior_covariance: tuple[tuple[float, ...], ...] | None = None
    rotor_confidence: float = 0.0
    autopilot: AutopilotLoop | None = None

    @property
    def theta_covariance(self) -> np.ndarray:
        """The prior covariance of relative θ, shape (6, 6) (``prior_covariance`` or its
        diagonal default)."""
        if self.prior_covariance is not None:
            return np.array(self.prior_covariance, dtype=float).reshape(6, 6)
        return np.eye(6) * self.prior_relative_sigma**2

    @property
    def start_pose(self) -> np.ndarray:
        """[x, y, z, yaw] of the start hover."""
        if self.start is not None:
            return np.asarray(self.start, dtype=float)
        b = np.asarray(self.box, dtype=float)
        return np.array([*(0.5 * (b[:3] + b[3:])), 0.0])
