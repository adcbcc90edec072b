"""Re-planning in flight: an opening flight, estimate, plan the rest, fly it, in one stream run.

The paper names re-planning as future work; here it turns ``--iterations`` into one
continuous flight whose plan is robust to the prior. `run_replanned_stream` streams the
opening trajectory file (`mavsysid.pipeline.stream.run_stream`) with a
continuation (`mavsysid.flight.ground.continuation`) that, while the vehicle holds at the
opening's end:

1. estimates θ̂ and its covariance Σ from the pose recorded so far (the pipeline of
   ``mavsysid estimate``: `load_flight` from the opening's first setpoint on, then
   `mavsysid.estimation.estimate`), on a snapshot of the complete rows of
   ``pose.csv``; when its rotor speeds are zero throughout (no ESC telemetry, e.g.
   ArduCopter SITL with ``SIM_ESC_TELEM 0``), on a snapshot of the flight's ``flight.tlog``
   instead, whose reader turns SERVO_OUTPUT_RAW into rotor speeds through the vehicle's
   motor curve (`mavsysid.formats.tlog`), windowed from the same start (pose.csv and the
   tlog's pose share the vehicle's clock) (`opening_log`); a refused estimate leaves the
   prior belief (`belief_after_opening`); an accepted one also tells the noise its filter
   met (pose σ and rate, the unmodelled force and moment fitted: `opening_belief`);
2. plans the rest of the budget for ``config.with_parameters(θ̂)`` at that noise
   (`mavsysid.pipeline.plan.for_noise_met`) from the hover where the
   opening ended (pulled in to the rotor clearance from the box's walls, as a plan's start
   must be, when the opening ended closer: `rest_start`; the streamer flies there first),
   with the posterior as the planner's prior (a parameter answered at or below 0, c_D at
   its bound, keeps the prior's value and σ: `positive_belief`): ``prior_covariance`` = Σ
   relative to θ̂ (Σ_jk / (θ̂_j θ̂_k)), which also sets the chance-constrained rotor
   check's spread, at the most confident rotor check that admits a flight
   (`plan_most_confident`; the z used goes into meta.json);
3. returns the plan; the streamer checks it like the first (box, limits) and flies it.

``meta.json`` records the segments (``opening``, ``replanned``), the estimate used (θ̂, σ,
Σ), the predicted D-optimality and the estimation and planning times. A failed estimate or
plan, or a refused plan, lands the vehicle and the run fails (exit 3) with one line.

The belief steps (`prior_estimate`, `belief_after_opening`, `relative_covariance`) are also
those of the offline evaluation of re-planning (`mavsysid.experiments.replanned_flight`).
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation import (
    EstimationResult,
    EstimatorSettings,
    NoiseMet,
    ParameterEstimate,
    estimate,
    load_flight,
)
from mavsysid.flight.ground.continuation import Continuation, FlightSoFar, NextSegment
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.formats.poselog import read_pose_log
from mavsysid.formats.trajectory_file import read_trajectory
from mavsysid.pipeline.plan import describe_noise, for_noise_met
from mavsysid.pipeline.stream import StreamOutcome, run_stream
from mavsysid.planner.plan_request import rotor_clearance
from mavsysid.planner.robust_plan import plan_most_confident
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import InputError, JobFailedError

__all__ = [
    "FEEDBACK_HEADROOM",
    "ReplanSettings",
    "belief_after_opening",
    "opening_belief",
    "opening_log",
    "positive_belief",
    "prior_estimate",
    "relative_covariance",
    "replanning_continuation",
    "rest_start",
    "run_replanned_stream",
    "snapshot_pose",
    "snapshot_tlog",
]


#: Rotor n² share the re-planned rest leaves free at each end for the autopilot's feedback:
#: with motor lag (25 ms) a plan on the rotor limit saturates 14–25 % of the control ticks
#: even when planned with the true θ; 0.1 brings that to 0.4–1.6 % (docs/benchmarks.md,
#: "Rotor headroom").
FEEDBACK_HEADROOM = 0.1


@dataclass(frozen=True)
class ReplanSettings:
    """How the rest of a flight is planned after its opening.

    Attributes
    ----------
    budget : float
        Whole flight's trajectory time, s, the opening included; the rest is planned.
    planner : PlannerSettings
        The re-planning's settings; its budget, box, start and prior_covariance are
        replaced by the rest, the flight box, the hold and the posterior. Planning time is
        hover time: keep it short (``max_samples`` for a seed-reproducible plan).
    estimator : EstimatorSettings or None
        Settings of the estimate from the opening (None: the defaults of ``estimate``).
    min_rest : float
        A rest shorter than this (s) is not planned: the vehicle lands.
    rounds : int
        Re-plans at most this many times (1: an opening and one re-planned rest).
    """

    budget: float
    planner: PlannerSettings = field(default_factory=lambda: PlannerSettings(
        planning_time=10.0, rotor_headroom=FEEDBACK_HEADROOM))
    estimator: EstimatorSettings | None = None
    min_rest: float = 2.0
    rounds: int = 1


def prior_estimate(prior: VehicleConfig, settings: PlannerSettings) -> ParameterEstimate:
    """The planner's θ belief as an estimate (SI): the config's θ and the settings' prior
    (``PlannerSettings.theta_covariance``, relative to θ).

    Parameters
    ----------
    prior : VehicleConfig
        The vehicle as known before flying; its θ is the mean.
    settings : PlannerSettings
        The planner's prior (``prior_covariance`` or ``prior_relative_sigma``).
    """
    theta = prior.theta
    return ParameterEstimate(theta.copy(), settings.theta_covariance * np.outer(theta, theta))


def belief_after_opening(estimate: Callable[[], ParameterEstimate], prior: ParameterEstimate
                         ) -> tuple[ParameterEstimate, str | None]:
    """The opening's estimate, or ``prior`` and the refusal's line when ``estimate`` refuses.

    A refused estimate is no belief to plan aggressively from; the belief the opening was
    planned from is, and its chance-constrained rotor check keeps the rest as gentle as the
    opening that flew. The whole flight is estimated (and may be refused) afterwards.

    Parameters
    ----------
    estimate : callable
        Returns the opening's estimate (θ̂, Σ in SI), or raises `JobFailedError` to refuse.
    prior : ParameterEstimate
        The belief the opening was planned from (`prior_estimate`).

    Returns
    -------
    belief : ParameterEstimate
    refusal : str or None
        The refusal's first line, None when the estimate was accepted.
    """
    try:
        return estimate(), None
    except JobFailedError as refusal:
        return prior, str(refusal).splitlines()[0]


def relative_covariance(estimate: ParameterEstimate) -> tuple[tuple[float, ...], ...]:
    """Σ relative to the estimate's θ̂: Σ_ij / (θ̂_i θ̂_j), as ``prior_covariance`` takes it.

    Parameters
    ----------
    estimate : ParameterEstimate
        θ̂ and Σ, SI.

    Raises
    ------
    JobFailedError
        A θ̂ component is not positive (the opening's filter diverged): no relative belief.
    """
    theta = np.asarray(estimate.value, dtype=float)
    if not np.all(np.isfinite(theta)) or np.any(theta <= 0.0):
        raise JobFailedError("the opening flight's estimate has a non-positive parameter "
                             f"({', '.join(f'{v:.3g}' for v in theta)}): cannot re-plan from it")
    rel = np.asarray(estimate.covariance, dtype=float) / np.outer(theta, theta)
    rel = 0.5 * (rel + rel.T)
    return tuple(tuple(float(v) for v in row) for row in rel)


def snapshot_pose(pose: Path, directory: Path) -> Path:
    """Copy the complete rows of a pose log being written into ``directory``; the copy.

    The streamer appends rows while the estimator reads; a row cut mid-write is left out.

    Parameters
    ----------
    pose : Path
        The pose log being written.
    directory : Path
        Folder the copy goes into.
    """
    data = Path(pose).read_bytes()
    out = Path(directory) / Path(pose).name
    out.write_bytes(data[: data.rfind(b"\n") + 1])
    return out


def snapshot_tlog(tlog: Path, directory: Path) -> Path:
    """Copy a tlog being written into ``directory``; the copy.

    `mavsysid.formats.tlog.TlogWriter` writes each record with one ``write``, so the bytes
    present are whole records (a record cut mid-write at the end is left out by the
    reader).

    Parameters
    ----------
    tlog : Path
        The tlog being written.
    directory : Path
        Folder the copy goes into.
    """
    out = Path(directory) / Path(tlog).name
    out.write_bytes(Path(tlog).read_bytes())
    return out


def opening_log(so_far: FlightSoFar, directory: Path) -> Path:
    """Snapshot, into ``directory``, the log the opening is estimated from; its path.

    ``pose.csv`` (the autopilot's pose, rotor speeds from ESC telemetry), or, when its
    rotor speeds are zero throughout (no ESC telemetry arrived), the flight's
    ``flight.tlog``, whose reader takes the rotor speeds from the motor outputs through
    the vehicle's motor curve. Both are on the vehicle's clock, so
    `FlightSoFar.window_start` windows either.

    Parameters
    ----------
    so_far : FlightSoFar
        The flight so far: its directory, pose log and vehicle.
    directory : Path
        Folder the snapshot goes into.
    """
    pose = snapshot_pose(so_far.pose, directory)
    tlog = Path(so_far.directory) / "flight.tlog"
    try:
        rotors = read_pose_log(pose, so_far.config.rotor_count).rotor_speeds
    except InputError:
        return pose  # the estimate says what is wrong with it
    if np.any(rotors != 0.0) or not tlog.is_file():
        return pose
    return snapshot_tlog(tlog, directory)


def rest_start(hover: tuple[float, ...], box: tuple[float, ...], config: VehicleConfig
               ) -> tuple[float, float, float, float]:
    """Where the rest is planned from: the hold, pulled in to the rotor clearance from the
    box's walls.

    A plan keeps the centre of gravity inside the box, so an opening may end closer to a
    wall than a plan may start (`mavsysid.planner.plan_request.rotor_clearance`); the
    rest then starts at the nearest point far enough inside, and the streamer's smooth
    move flies there from the hold.

    Parameters
    ----------
    hover : tuple of 4 float
        The hold [x, y, z, yaw], m and rad (ENU).
    box : tuple of 6 float
        The flight box, m.
    config : VehicleConfig
        The vehicle: its rotor positions.
    """
    clearance = rotor_clearance(config)
    low, high = np.asarray(box[:3]) + clearance, np.asarray(box[3:]) - clearance
    position = np.clip(np.asarray(hover[:3], dtype=float), low, np.maximum(low, high))
    return (*(float(v) for v in position), float(hover[3]))


def _estimate(so_far: FlightSoFar, settings: EstimatorSettings | None) -> EstimationResult:
    """The estimate of the flight so far (the ``estimate`` pipeline, from the opening's
    start)."""
    with tempfile.TemporaryDirectory(prefix="mavsysid-replan-") as tmp:
        log = opening_log(so_far, Path(tmp))
        flight = load_flight(log, so_far.config, start=so_far.window_start)
        source = so_far.pose if log.suffix == ".csv" else Path(so_far.directory) / log.name
        return estimate(replace(flight, source=str(source)), so_far.config, settings)


def opening_belief(result: Callable[[], EstimationResult], prior: ParameterEstimate
                   ) -> tuple[ParameterEstimate, NoiseMet | None, str | None]:
    """`belief_after_opening` with the noise the opening's filter met.

    Parameters
    ----------
    result : callable
        Returns the opening's estimate, or raises `JobFailedError` to refuse.
    prior : ParameterEstimate
        The belief the opening was planned from.

    Returns
    -------
    belief : ParameterEstimate
    noise : NoiseMet or None
        What the opening's filter met (None when refused or when no filter ran): the rest
        is planned for it (`mavsysid.pipeline.plan.for_noise_met`).
    refusal : str or None
    """
    met: list[NoiseMet | None] = [None]

    def final() -> ParameterEstimate:
        done = result()
        met[0] = done.noise_met
        return done.final.theta

    belief, refusal = belief_after_opening(final, prior)
    return belief, (met[0] if refusal is None else None), refusal


def positive_belief(belief: ParameterEstimate, prior: ParameterEstimate
                    ) -> tuple[ParameterEstimate, tuple[str, ...]]:
    """``belief`` with the prior's value and σ (no cross terms) for each parameter whose
    value is not positive, and their names.

    The planner's model needs a positive θ and its belief is relative to it; a parameter
    the opening answered at 0 (c_D at its bound) or below is planned for as before the
    opening.

    Parameters
    ----------
    belief : ParameterEstimate
        The opening's θ belief, SI.
    prior : ParameterEstimate
        The belief the opening was planned from (`prior_estimate`), same quantities.
    """
    value = np.asarray(belief.value, dtype=float).copy()
    bad = ~(np.isfinite(value) & (value > 0.0))
    if not bad.any():
        return belief, ()
    covariance = np.asarray(belief.covariance, dtype=float).copy()
    for j in np.flatnonzero(bad):
        value[j] = prior.value[j]
        covariance[j, :] = covariance[:, j] = 0.0
        covariance[j, j] = prior.covariance[j, j]
    return (ParameterEstimate(value, covariance, belief.names),
            tuple(belief.names[j] for j in np.flatnonzero(bad)))


def replanning_continuation(settings: ReplanSettings,
                            say: Callable[[str], None] | None = None) -> Continuation:
    """The continuation that estimates from the flight so far and plans its rest.

    Returns None (land) after ``settings.rounds`` re-plans, or once less than
    ``settings.min_rest`` of the budget is left.

    Parameters
    ----------
    settings : ReplanSettings
        Rounds, budget and the planner's settings.
    say : callable, optional
        Receives one line per stage.
    """
    say = say or (lambda _text: None)

    def next_segment(so_far: FlightSoFar) -> NextSegment | None:
        rest = settings.budget - so_far.flown
        if rest < settings.min_rest or so_far.segments > settings.rounds:
            return None
        began = time.monotonic()
        prior = prior_estimate(so_far.config, settings.planner)
        estimate, noise, refusal = opening_belief(
            lambda: _estimate(so_far, settings.estimator), prior)
        estimate, kept = positive_belief(estimate, prior)
        if kept:
            say(f"the opening answered {', '.join(kept)} at or below 0: the rest is planned "
                "with their prior value and σ")
        estimated = time.monotonic()
        if refusal is None:
            say("estimate after {:.1f} s: σ/θ {}".format(
                so_far.flown, ", ".join(f"{100 * s:.1f} %" for s in estimate.relative_sigma)))
        else:
            say(f"estimate after {so_far.flown:.1f} s refused ({refusal}); the rest is "
                "planned from the prior belief")
        rel = relative_covariance(estimate)
        start = rest_start(so_far.hover, so_far.box, so_far.config)
        if start != tuple(so_far.hover):
            say("the hold is within the rotor clearance of the box's walls: the rest starts "
                "at {} m".format(", ".join(f"{v:.2f}" for v in start[:3])))
        planner = replace(settings.planner, budget=rest, box=tuple(so_far.box),
                          start=start,
                          prior_covariance=rel,
                          autopilot_limits=(so_far.autopilot_limits
                                            or settings.planner.autopilot_limits))
        if noise is not None:
            say(f"the rest is planned for the noise the opening met: {describe_noise(noise)}")
        model, planner = for_noise_met(so_far.config.with_parameters(estimate.value), planner,
                                       noise)
        confident = plan_most_confident(model, planner)
        plan, planner = confident.result, replace(
            planner, rotor_confidence=confident.rotor_confidence)
        planned = time.monotonic()
        say(f"re-planned {plan.trajectory.duration:.1f} s at rotor confidence "
            f"z = {planner.rotor_confidence:g} in {planned - estimated:.1f} s "
            f"(estimate {estimated - began:.1f} s), predicted D-opt {plan.predicted_dopt:.3g}")
        record: dict[str, Any] = {
            "estimate": {"theta": estimate.value.tolist(), "sigma": estimate.sigma.tolist(),
                         "covariance": estimate.covariance.tolist(),
                         "from_flown_s": so_far.flown, "refused": refusal,
                         "noise_met": None if noise is None else asdict(noise)},
            "estimation_s": estimated - began, "planning_s": planned - estimated,
            "planner": {"budget": rest, "max_samples": planner.max_samples,
                        "planning_time": (planner.planning_time if math.isfinite(
                            planner.planning_time) else None), "seed": planner.seed,
                        "rotor_confidence": planner.rotor_confidence,
                        "start": list(start)},
            "predicted_dopt": plan.predicted_dopt}
        return NextSegment(plan.trajectory, "replanned", record)

    return next_segment


def run_replanned_stream(trajectory: str | Path, stream: StreamSettings, replan: ReplanSettings,
                         vehicle: str | Path | None = None,
                         say: Callable[[str], None] | None = None,
                         progress: bool = True) -> StreamOutcome:
    """Fly the opening ``trajectory``, then the rest of ``replan.budget`` planned in flight.

    Parameters
    ----------
    trajectory : str or Path
        The opening's trajectory file (``mavsysid plan --budget`` a few seconds).
    stream : StreamSettings
    replan : ReplanSettings
    vehicle : str or Path, optional
        Shipped vehicle name or TOML path (default: the one stored in the file); its
        nominal θ is the estimator's prior.
    say : callable, optional
    progress : bool

    Raises
    ------
    InputError
        Bad input (`run_stream`'s), or a budget not longer than the opening.
    JobFailedError
        Refused or aborted; a failed or refused re-plan after landing.
    """
    opening = read_trajectory(trajectory).trajectory.duration
    if not replan.budget > opening:
        raise InputError(f"--replan-budget {replan.budget:g}: must exceed the opening's "
                         f"{opening:.1f} s ({trajectory})")
    return run_stream(trajectory, stream, vehicle, say, progress,
                      continuation=replanning_continuation(replan, say))
