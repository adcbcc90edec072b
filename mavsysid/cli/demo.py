"""``mavsysid demo``: the whole experiment on the simulated vehicle, end to end.

1. **Plan** an informative flight for the vehicle's nominal (prior) model.
2. **Fly** it: start ``mavsysid sim`` as its own process — a vehicle whose true θ differs
   from the nominal by a seeded, hidden factor — and stream the plan to it over MAVLink
   on UDP loopback, recording ``pose.csv``, ``flight.tlog`` and ``meta.json``.
3. **Estimate** θ with the paper's EKF from the part of the recorded pose log where the
   plan was flown.
4. **Diagnose** the identified model on the last flight (`mavsysid.discrepancy.diagnosis`): does a
   named physical effect explain what the model still gets wrong?

With
``iterations > 1`` steps 1–3 repeat with the updated model (the paper's future work).

Everything goes into one run folder (``logs/demo-<time>/``): the plans, the flight
directories, the simulator's truth logs, ``estimate.json`` and ``demo.rrd`` (one Rerun
recording of every stage). `run_demo` does the work; `main` is the console layer.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mavsysid.cli.plan import run_plan
from mavsysid.cli.simulate import parse_hidden_effects
from mavsysid.cli.stream import run_stream
from mavsysid.discrepancy.diagnosis import Diagnosis, diagnose_flight
from mavsysid.discrepancy.report import write_diagnosis_json
from mavsysid.errors import InputError, JobFailedError
from mavsysid.estimation.estimator import EstimatorSettings, estimate_parameters
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import EstimationResult, ParameterEstimate
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.formats.flight_dir import new_flight_dir, read_meta, write_json_atomic
from mavsysid.formats.trajectory_file import write_trajectory
from mavsysid.planner.results import PlannerSettings, PlanResult
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle

__all__ = ["DemoResult", "DemoRound", "DemoSettings", "run_demo"]

#: Largest hidden deviation of the simulated vehicle's θ from the nominal, relative, per
#: parameter. c_T stays close: the simulated autopilot, like a real one without hover
#: throttle learning, holds altitude with the nominal c_T and has no integral action.
HIDDEN_SPREAD = np.array([0.05, 0.3, 0.3, 0.3, 0.3, 0.3])


#: Share of the top rotor speed the plans leave to the autopilot's feedback: the vehicle's
#: true θ is not the model's, and a plan at the model's rotor limit saturates the real one.
ROTOR_HEADROOM = 0.15
#: Share of the body-rate, yaw-acceleration and thrust envelope the demo plans in: room
#: for an autopilot that follows 50 Hz setpoints with a wrong model.
ENVELOPE = 0.7

#: Pose and rotor-speed telemetry rate asked of the vehicle, Hz. The EKF takes rotor speeds
#: as linear between samples; the autopilot's speeds change with every 50 Hz setpoint, and
#: at 100 Hz that already biased c_D by 5σ (1σ at 200 Hz, on the same flight). 250 Hz is
#: a whole number of the simulated autopilot's 2 ms ticks, so the samples are uniform.
TELEMETRY_RATE = 250.0


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


def hidden_scale(config: VehicleConfig, seed: int) -> np.ndarray:
    """True θ / nominal θ of the simulated vehicle: seeded, within ±`HIDDEN_SPREAD`, and
    drawn again until the true inertia is as physical as the nominal one (a true θ must
    pass the same config checks, since plans carry the updated model)."""
    rng = np.random.default_rng([seed, 7])
    j = config.theta[3:]
    slack = max(1.0, float(np.max(j / (j.sum() - j))))
    while True:
        scale = 1.0 + rng.uniform(-HIDDEN_SPREAD, HIDDEN_SPREAD)
        jt = j * scale[3:]
        if np.all(jt <= slack * (jt.sum() - jt)):
            return scale


class _SimVehicle:
    """``mavsysid sim`` in its own process, sending to a loopback port."""

    def __init__(self, directory: Path, vehicle: str, scale: np.ndarray, port: int,
                 speedup: float, seed: int, hidden: tuple[str, ...] = ()) -> None:
        self.directory = directory
        directory.mkdir(parents=True, exist_ok=True)
        self._out = open(directory / "sim.out", "wb")  # noqa: SIM115 - the child writes it
        args = ["sim", "--connect", f"udpout:127.0.0.1:{port}", "--vehicle", vehicle,
                "--speedup", f"{speedup:g}", "--seed", str(seed), "--truth-log",
                str(directory / "truth"), "--theta-scale", ",".join(f"{v:.12g}" for v in scale)]
        for text in hidden:
            args += ["--hidden-effect", text]
        self.process = subprocess.Popen([sys.executable, "-m", "mavsysid", *args],
                                        stdout=self._out, stderr=subprocess.STDOUT)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        self._out.close()


def with_headroom(model: VehicleConfig) -> VehicleConfig:
    """The model the demo plans with: `ROTOR_HEADROOM` off its top rotor speed, and its
    body rate, yaw acceleration and thrust above hover scaled to `ENVELOPE`."""
    lim = model.limits
    return replace(model, limits=replace(
        lim, rotor_speed_max=(1.0 - ROTOR_HEADROOM) * lim.rotor_speed_max,
        body_rate_max=ENVELOPE * lim.body_rate_max,
        yaw_acceleration_max=ENVELOPE * lim.yaw_acceleration_max,
        thrust_max_ratio=1.0 + ENVELOPE * (lim.thrust_max_ratio - 1.0)))


def trajectory_window(flight_dir: Path, model: VehicleConfig) -> FlightData:
    """The recorded flight while the plan was flown (the streamer's ``trajectory_window``):
    the ground, take-off and landing are not in the model and stay out of the estimate."""
    flight = load_flight(flight_dir / "pose.csv", model)
    window = read_meta(flight_dir / "meta.json").get("trajectory_window")
    if not window:
        raise JobFailedError(f"{flight_dir}: the flight has no trajectory window; it did not "
                             "fly the plan")
    return flight.time_slice(float(window["start"]), float(window["end"]))


def _fly(plan_file: Path, directory: Path, settings: DemoSettings, scale: np.ndarray,
         seed: int, say: Callable[[str], None], progress: bool) -> tuple[Path, float]:
    """Start the simulated vehicle, stream the plan to it, stop it; the flight directory."""
    port = free_udp_port()
    sim = _SimVehicle(directory / "sim", settings.vehicle, scale, port, settings.speedup, seed,
                      settings.hidden_effects)
    try:
        time.sleep(0.2)
        if sim.process.poll() is not None:
            raise JobFailedError(f"the simulated vehicle did not start; see {sim.directory}")
        stream = StreamSettings(connect=f"udp:127.0.0.1:{port}", speedup=settings.speedup,
                                telemetry_rate=TELEMETRY_RATE, log_dir=directory)
        outcome = run_stream(plan_file, stream, say=say, progress=progress)
    finally:
        sim.stop()
    return outcome.directory, float(outcome.meta.get("tracking", {}).get("rms_m", np.nan))


def run_demo(settings: DemoSettings, say: Callable[[str], None] | None = None,
             progress: bool = True, name: str | None = None, record: bool = True
             ) -> DemoResult:
    """Plan, fly over MAVLink and estimate, ``settings.iterations`` times."""
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
            f"(simulated vehicle, {settings.speedup:g}x real time)")
        flight_dir, rms = _fly(plan_file, directory / f"round-{iteration}", settings, scale,
                               settings.seed + iteration - 1, say, progress)
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
    round's planned and reached D-opt."""
    import rerun as rr

    from mavsysid.discrepancy.recording import log_diagnosis
    from mavsysid.estimation.recording import log_estimation
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


def format_summary(result: DemoResult) -> str:
    """The one-screen summary: planned vs achieved σ, estimates vs the simulator's truth."""
    truth = result.true_theta
    lines = [f"mavsysid demo: {result.config.name}, {len(result.rounds)} round(s), "
             f"run folder {result.directory}", ""]
    for r in result.rounds:
        planned = np.asarray(r.plan.predicted_sigma)[-1] / np.abs(r.plan.config.theta)
        achieved = r.estimate.sigma / np.abs(truth)
        error = r.estimate.value / truth - 1.0
        lines.append(f"round {r.iteration}: flew {r.plan.trajectory.duration:.1f} s, tracking "
                     f"RMS {100 * r.tracking_rms:.1f} cm, D-opt planned "
                     f"{r.plan.predicted_dopt:.3g}, reached "
                     f"{r.estimate.d_optimality:.3g}")
        lines.append(f"  {'parameter':<10}{'truth':>12}{'estimate':>12}{'error':>9}"
                     f"{'σ planned':>11}{'σ reached':>11}")
        for j, n in enumerate(PARAMETER_NAMES):
            lines.append(f"  {n:<10}{truth[j]:>12.4g}{r.estimate.value[j]:>12.4g}"
                         f"{100 * error[j]:>8.2f}%{100 * planned[j]:>10.3f}%"
                         f"{100 * achieved[j]:>10.3f}%")
    if result.diagnosis is not None:
        lines += ["", *diagnosis_lines(result.diagnosis)]
    lines.append("")
    lines += [f"  {k:<10} {v}" for k, v in result.files.items()]
    return "\n".join(lines)


def diagnosis_lines(diagnosis: Diagnosis) -> list[str]:
    """The diagnosis in a few lines: the named effects and the gap, or that there is none."""
    rms = diagnosis.gap.before.rms
    if not diagnosis.effects:
        return ["diagnosis: no significant discrepancy between the identified model and the "
                "flight (no candidate effect explains the residual; held-out residual RMS "
                f"force {np.linalg.norm(rms[:3]):.3g} m/s², angular acceleration "
                f"{np.linalg.norm(rms[3:]):.3g} rad/s²)"]
    lines = ["diagnosis: the model misses " + ", ".join(e.effect.name for e in
                                                         diagnosis.effects)]
    for e in diagnosis.effects:
        values = ", ".join(f"{k} = {v:.4g}" for k, v in e.effect.as_dict().items())
        lines.append(f"  {e.effect.name}: {values}")
    lines.append(f"  adding it shrinks the held-out gap by {100 * diagnosis.gap.shrink:.0f} %")
    return lines


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid demo``."""
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path (default: firefly)")
    parser.add_argument("--time", type=float, default=DemoSettings.planning_time, metavar="S",
                        help=f"planning time per round, s (default: "
                        f"{DemoSettings.planning_time:g})")
    parser.add_argument("--budget", type=float, default=30.0, metavar="S",
                        help="flight-time budget, s (default: 30)")
    parser.add_argument("--iterations", type=int, default=1,
                        help="plan–fly–estimate rounds, each with the updated model (default: 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default: 0)")
    parser.add_argument("--speedup", type=float, default=DemoSettings.speedup, metavar="K",
                        help=f"simulated seconds per wall second (default: "
                        f"{DemoSettings.speedup:g})")
    parser.add_argument("--logs", type=Path, default=Path("logs"),
                        help="folder for the run folder (default: logs)")
    parser.add_argument("--name", help="run folder name (default: a timestamp)")
    parser.add_argument("--refine-steps", type=int, default=0, metavar="N",
                        help="planner refinement steps (default: 0, the paper's search alone)")
    parser.add_argument("--hidden-effect", action="append", default=[],
                        metavar="NAME:KEY=VALUE,...",
                        help="give the simulated vehicle an effect the model lacks, for the "
                        "diagnosis to find (repeatable), e.g. motor_lag:tau=0.04")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    verbose = args.verbosity >= 0

    def say(text: str) -> None:
        if verbose:
            print(f"mavsysid demo: {text}", file=sys.stderr, flush=True)

    settings = DemoSettings(vehicle=args.vehicle, planning_time=args.time, budget=args.budget,
                            iterations=args.iterations, seed=args.seed, speedup=args.speedup,
                            logs=args.logs, hidden_effects=tuple(args.hidden_effect),
                            refine_steps=args.refine_steps)
    result = run_demo(settings, say, progress=verbose, name=args.name)
    print(format_summary(result))
    return 0
