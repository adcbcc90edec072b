"""The whole experiment on a real autopilot, in one job: plan within the limits read from
the vehicle, fly the plan, estimate θ from the flight's own log, report.

`run_autopilot_experiment` is what ``mavsysid experiment`` calls; tests call it directly.
Each stage is the job its own command runs (`mavsysid.pipeline.plan`,
`mavsysid.pipeline.stream`, `mavsysid.pipeline.estimate`), so the experiment refuses what
they refuse, in their words. The flight directory keeps everything: the trajectory file
(``trajectory.json``) next to the streamer's ``flight.tlog``, ``pose.csv`` and
``meta.json``, the vehicle's own log downloaded after landing (``autopilot.bin`` /
``autopilot.ulg``, with ``StreamSettings.download_log``), and ``estimate.json`` once θ is
estimated. The plan is written first as
``LOG_DIR/trajectory-seedN.json`` (the flight directory is named after it) and stays there
when the flight is refused. A dry run (``stream.dry_run``) reads the limits, plans, and
runs every check of the flight on the vehicle without arming or changing anything; it
estimates nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from mavsysid.estimation import (
    EstimatorSettings,
    NoiseMet,
    write_estimate_json,
)
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.pipeline.estimate import EstimateRun, run_estimate
from mavsysid.pipeline.plan import for_noise_met, read_autopilot, run_plan
from mavsysid.pipeline.stream import StreamOutcome, run_stream
from mavsysid.planner.plan_file import write_trajectory
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import JobFailedError

__all__ = ["ExperimentOutcome", "run_autopilot_experiment"]


@dataclass(frozen=True)
class ExperimentOutcome:
    """A finished experiment.

    Attributes
    ----------
    limits : str
        Where the autopilot's limits came from and what they are (one line).
    plan : PlanResult
        The planned flight (its ``shortfall`` note says when it is short of the budget).
    flight : StreamOutcome
        The flight directory and its ``meta.json``.
    trajectory : Path
        The trajectory file flown, in the flight directory.
    estimate : EstimateRun or None
        θ estimated from the flight's log (None after a dry run).
    estimate_file : Path or None
        ``estimate.json`` in the flight directory (None after a dry run).
    """

    limits: str
    plan: PlanResult
    flight: StreamOutcome
    trajectory: Path
    estimate: EstimateRun | None
    estimate_file: Path | None


def run_autopilot_experiment(vehicle: str | Path, planner: PlannerSettings,
                             stream: StreamSettings,
                             estimator: EstimatorSettings | None = None,
                             say: Callable[[str], None] | None = None,
                             progress: bool = True,
                             autopilot_model: bool = False,
                             noise: NoiseMet | None = None) -> ExperimentOutcome:
    """Plan within the vehicle's limits, fly it on ``stream.connect``, estimate θ from its log.

    Parameters
    ----------
    vehicle : str or Path
        Shipped vehicle name or TOML path: the plan's model and the estimate's prior.
    planner : PlannerSettings
        Budget, box, planning time, seed, …; its ``autopilot_limits`` are replaced by the
        limits read from the vehicle.
    stream : StreamSettings
        The link (``connect``), rates, guards and where the flight directory goes. The
        plan is made within the vehicle's limits, so ``set_limits`` is not needed.
    estimator : EstimatorSettings, optional
        ``mavsysid estimate``'s defaults when None.
    say : callable, optional
        Receives one-line status messages.
    progress : bool
        Progress bars while planning and streaming.
    autopilot_model : bool
        Also read the autopilot's loop parameters and plan on the flight it is predicted
        to fly (`PlannerSettings.autopilot`); else the setpoints count as flown exactly.
    noise : NoiseMet, optional
        Plan for the noise the estimator met on an earlier flight of the vehicle
        (`mavsysid.pipeline.plan.for_noise_met`); the estimate itself uses the vehicle file.

    Returns
    -------
    ExperimentOutcome

    Raises
    ------
    InputError
        Bad vehicle, settings or link.
    JobFailedError
        No vehicle answered, no plan was found, the flight was refused or aborted (its
        directory keeps what was recorded), or the estimate was refused: one line naming
        the stage, and for a flown experiment its flight directory.
    """
    say = say or (lambda _text: None)
    say(f"reading the autopilot's limits from the vehicle on {stream.connect}")
    envelope = read_autopilot(stream.connect, stream.signing_key, stream.heartbeat_timeout,
                              say, loop=autopilot_model)
    source = envelope.source
    say(f"planning within the limits of {source}")
    model, planner = for_noise_met(load_vehicle(vehicle), planner, noise)
    plan = run_plan(model, replace(planner, autopilot_limits=envelope.limits,
                                   autopilot=envelope.loop), progress=progress)
    if plan.shortfall:
        say(f"warning: {plan.shortfall}")
    stream.log_dir.mkdir(parents=True, exist_ok=True)
    staged = stream.log_dir / f"trajectory-seed{planner.seed}.json"
    write_trajectory(staged, plan)
    flight = run_stream(staged, stream, vehicle, say, progress)
    trajectory = flight.directory / "trajectory.json"
    staged.replace(trajectory)
    if stream.dry_run:
        return ExperimentOutcome(source, plan, flight, trajectory, None, None)
    say(f"estimating θ from {flight.directory} (its log with the most telling rotor speeds)")
    try:
        estimate = run_estimate(flight.directory, vehicle, settings=estimator)
    except JobFailedError as refused:
        raise JobFailedError(f"flown and recorded in {flight.directory}, but no estimate: "
                             f"{refused}") from refused
    log = Path(estimate.flight.source)
    say(f"estimated from {log.name}")
    estimate_file = flight.directory / "estimate.json"
    write_estimate_json(estimate_file, estimate.result, estimate.config, log)
    return ExperimentOutcome(source, plan, flight, trajectory, estimate, estimate_file)
