"""The whole experiment on the simulated vehicle, end to end (the work of ``mavsysid demo``).

1. **Plan** an informative flight for the vehicle's nominal (prior) model.
2. **Fly** it: start ``mavsysid sim`` as its own process — a vehicle whose true θ differs
   from the nominal by a seeded, hidden factor — and stream the plan to it over MAVLink
   on UDP loopback, recording ``pose.csv``, ``flight.tlog`` and ``meta.json``
   (`mavsysid.pipeline.demo_flight`).
3. **Estimate** θ with the paper's EKF from the part of the recorded pose log where the
   plan was flown.
4. **Diagnose** the identified model on the last flight
   (`mavsysid.discrepancy.diagnosis`): does a named physical effect explain what the model
   still gets wrong?

With
``iterations > 1`` steps 1–3 repeat with the updated model (the paper's future work).

Everything goes into one run folder (``logs/demo-<time>/``): the plans, the flight
directories, the simulator's truth logs, ``estimate.json`` and ``demo.rrd`` (one Rerun
recording of every stage). `run_demo` does the work; the ``mavsysid demo`` command only
parses, calls it and prints.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from mavsysid.discrepancy.diagnosis import Diagnosis, diagnose_flight
from mavsysid.discrepancy.report import write_diagnosis_json
from mavsysid.estimation import (
    EstimationResult,
    EstimatorSettings,
    FlightData,
    ParameterEstimate,
    estimate_parameters,
)
from mavsysid.formats.flight_dir import new_flight_dir, write_json_atomic
from mavsysid.pipeline.demo_flight import (
    fly_over_mavlink,
    hidden_scale,
    trajectory_window,
    with_headroom,
)
from mavsysid.pipeline.plan import run_plan
from mavsysid.pipeline.simulate import parse_hidden_effects
from mavsysid.planner.plan_file import write_trajectory
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle

from mavsysid.errors import InputError

__all__ = ["DemoResult", "DemoRound", "DemoSettings", "run_demo", "write_demo_rrd"]


@dataclass(frozen=True)
class DemoSettings:
    """Choices of the demonstration.

    Attributes
    ----------
    vehicle : str
        Shipped vehicle name or TOML path: the nominal model.
    planning_time : float
        Planning time per round, s.
    budget : float
        Flight-time budget, s.
    iterations : int
        Plan–fly–estimate rounds.
    seed : int
        Seed of the hidden θ deviation, the planner and the simulator's noise.
    speedup : float
        Simulated time per wall second of the MAVLink flight.
    logs : Path
        Folder that receives the run folder.
    hidden_effects : tuple of str
        Effects the simulated vehicle has and the model does not (``NAME:KEY=VALUE,…``,
        as ``mavsysid sim --hidden-effect``), for the diagnosis to find.
    refine_steps : int
        Refinement steps of the planner; 0 (the paper's search alone) by default: refined
        plans hug every limit, and the simulated autopilot, which rebuilds jerk from 50 Hz
        acceleration setpoints, broke into a growing pitch oscillation on them (the
        offline simulator flies the same plans within 3 cm).
    """

    vehicle: str = "firefly"
    planning_time: float = 15.0
    budget: float = 30.0
    iterations: int = 1
    seed: int = 0
    speedup: float = 2.0
    logs: Path = Path("logs")
    hidden_effects: tuple[str, ...] = ()
    refine_steps: int = 0


@dataclass(frozen=True)
class DemoRound:
    """One plan–fly–estimate round."""

    iteration: int
    plan: PlanResult
    flight_dir: Path
    flight: FlightData
    estimation: EstimationResult
    tracking_rms: float

    @property
    def estimate(self) -> ParameterEstimate:
        """The filter's final θ and covariance (what the planner predicts), SI."""
        return self.estimation.filtered


@dataclass(frozen=True)
class DemoResult:
    """A finished demonstration."""

    directory: Path
    config: VehicleConfig
    true_theta: np.ndarray
    rounds: list[DemoRound] = field(default_factory=list)
    files: dict[str, Path] = field(default_factory=dict)
    diagnosis: Diagnosis | None = None


def run_demo(settings: DemoSettings, say: Callable[[str], None] | None = None,
             progress: bool = True, name: str | None = None, record: bool = True
             ) -> DemoResult:
    """Plan, fly over MAVLink and estimate, ``settings.iterations`` times.

    Parameters
    ----------
    settings : DemoSettings
        Vehicle, rounds, budgets, speed-up, hidden effects, seed.
    say : callable, optional
        Receives one line per stage.
    progress : bool
        Show the planner's progress bar.
    name : str, optional
        Name of the run folder (default: the local time).
    record : bool
        Write ``demo.rrd``.
    """
    say = say or (lambda _text: None)
    if settings.iterations < 1:
        raise InputError(f"--iterations {settings.iterations}: expected at least 1")
    if not settings.planning_time > 0.0:
        raise InputError(f"--time {settings.planning_time:g}: expected > 0 s")
    config = load_vehicle(settings.vehicle)
    parse_hidden_effects(settings.hidden_effects)  # refuse a bad one before flying
    scale = hidden_scale(config, settings.seed)
    truth = config.theta * scale
    directory = new_flight_dir(settings.logs, name or None)
    result = DemoResult(directory, config, truth)
    model = config
    for iteration in range(1, settings.iterations + 1):
        tag = f"[{iteration}/{settings.iterations}]"
        say(f"{tag} planning for {settings.planning_time:g} s with the model θ")
        plan = run_plan(with_headroom(model), PlannerSettings(
            budget=settings.budget, planning_time=settings.planning_time,
            seed=settings.seed + iteration - 1, refine_steps=settings.refine_steps),
            progress=progress)
        plan_file = directory / f"plan-{iteration}.json"
        write_trajectory(plan_file, plan)
        say(f"{tag} flying the {plan.trajectory.duration:.1f} s plan over MAVLink "
            f"(simulated vehicle, lock-step, up to {settings.speedup:g}x real time)")
        flight_dir, rms = fly_over_mavlink(plan_file, directory / f"round-{iteration}",
                                           settings.vehicle, scale, settings.speedup,
                                           settings.seed + iteration - 1,
                                           settings.hidden_effects, say, progress)
        say(f"{tag} estimating θ from {flight_dir / 'pose.csv'}")
        flight = trajectory_window(flight_dir, model)
        # The filter's covariance is what the planner predicts; its σ is also the honest
        # one here (the batch refinement's σ run optimistic on these telemetry logs).
        estimation = estimate_parameters(flight, model, EstimatorSettings(refine=False))
        result.rounds.append(DemoRound(iteration, plan, flight_dir, flight, estimation, rms))
        model = config.with_parameters(estimation.filtered.value)
    last = result.rounds[-1]
    say(f"diagnosing the identified model on {last.flight_dir / 'pose.csv'}")
    diagnosis = diagnose_flight(last.flight, config, theta=last.estimate.value,
                                known_effects=config.effects, progress=say)
    result = replace(result, diagnosis=diagnosis)
    result.files["diagnosis"] = directory / "diagnosis.json"
    write_diagnosis_json(result.files["diagnosis"], diagnosis, config, str(last.flight.source))
    result.files["estimate"] = directory / "estimate.json"
    write_json_atomic(result.files["estimate"], {
        "parameters": result.rounds[-1].estimate.as_dict(),
        "true_parameters": dict(zip(PARAMETER_NAMES, truth.tolist(), strict=True)),
        "rounds": [{"iteration": r.iteration, "flight": str(r.flight_dir),
                    "predicted_dopt": r.plan.predicted_dopt,
                    "reached_dopt": r.estimate.d_optimality,
                    "parameters": r.estimate.as_dict()} for r in result.rounds]})
    if record:
        say("writing the Rerun recording of every stage")
        result.files["recording"] = directory / "demo.rrd"
        write_demo_rrd(result.files["recording"], result)
    return result


def write_demo_rrd(path: Path, result: DemoResult) -> None:
    """One Rerun recording of every stage: the last round's plan and estimate, and each
    round's planned and reached D-opt.

    Parameters
    ----------
    path : Path
        The ``.rrd`` file.
    result : DemoResult
        The demo run.
    """
    import rerun as rr
    from mavsysid.discrepancy.recording import log_diagnosis
    from mavsysid.estimation import (
        log_estimation,
    )
    from mavsysid.formats.rerun_file import atomic_recording
    from mavsysid.planner.recording import log_plan

    with atomic_recording(path, "mavsysid", f"demo-{result.directory.name}",
                          f"demo {result.directory.name}") as rec:
        last = result.rounds[-1]
        log_plan(rec, last.plan)
        log_estimation(rec, last.estimation, last.flight)
        if result.diagnosis is not None:
            log_diagnosis(rec, result.diagnosis)
        for r in result.rounds:
            rec.set_time("round", sequence=r.iteration)
            rec.log("rounds/dopt/planned", rr.Scalars(r.plan.predicted_dopt))
            rec.log("rounds/dopt/reached", rr.Scalars(r.estimate.d_optimality))
