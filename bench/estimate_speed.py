"""Run time of ``mavsysid estimate`` on a 60 s, 500 Hz log (target: ≤ 20 s once compiled).

Simulates the built-in excitation for 60 s logged at 500 Hz into a temporary folder, runs
the estimate once (compiling the numba kernels into their cache), then times it again and
prints the time of each stage (from the estimator's own stage messages) and the total.
``--cli`` also times the whole command in a fresh process (imports included);
``--least-squares`` also solves the batch refinement's problem with
`scipy.optimize.least_squares` (`mavsysid.estimation.batch.refine`) for comparison.

    python bench/estimate_speed.py [--duration 60] [--rate 500] [--cli] [--least-squares]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from mavsysid.estimation.batch.refine import refine, shooting_problem, solve_least_squares
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    flight_initial_state_sigma,
)
from mavsysid.estimation.filter.likelihood import fit_noise_scale
from mavsysid.estimation.progress import stage_listener
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import prior_from_config
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.pipeline.estimate import run_estimate
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import MavsysidError


def timed_estimate(log: Path) -> tuple[list[tuple[float, str]], float, str]:
    """Stage messages with their start times (s), the total (s) and how the job ended."""
    stages: list[tuple[float, str]] = []
    start = time.perf_counter()
    outcome = "finished"
    with stage_listener(lambda m: stages.append((time.perf_counter() - start, m))):
        try:
            run_estimate(log)
        except MavsysidError as error:  # a refusal still timed every stage it ran
            outcome = f"refused: {error}"
    return stages, time.perf_counter() - start, outcome


def print_stages(stages: list[tuple[float, str]], total: float) -> None:
    """One line per stage (progress steps folded into their stage), then the total."""
    ends = [t for t, _ in stages[1:]] + [total]
    merged: dict[str, float] = {}
    for (t, message), end in zip(stages, ends, strict=True):
        name = message.split(" 1/")[0].split(":")[0].rstrip("0123456789/ ")
        merged[name] = merged.get(name, 0.0) + end - t
    for name, seconds in merged.items():
        print(f"  {seconds:7.2f} s  {name}")
    print(f"  {total:7.2f} s  total")


def batch_alone(log: Path, least_squares: bool) -> None:
    """Time the batch refinement by itself at the fitted noise level, and least_squares."""
    config = load_vehicle("firefly")
    flight = load_flight(log, config)
    prior = prior_from_config(config, EstimatorSettings())
    sigma = (config.noise.position_sigma, config.noise.attitude_sigma)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    fit = fit_noise_scale(flight, config, prior, sigma, state_sigma)
    model = ParameterEKF(fit.config, prior, sigma).model
    args = (flight, fit.run.states, fit.run.estimate, model, prior, sigma)
    truth = flight.true_theta
    for label, interval in (("every sample", 0.0), ("every 10 ms", 0.01)):
        start = time.perf_counter()
        batch = refine(*args, node_interval=interval)
        print(f"  batch refinement, nodes {label}: {time.perf_counter() - start:.2f} s, "
              f"{batch.iterations} iterations, cost {batch.cost_initial:.4g} → "
              f"{batch.cost_final:.10g}, max |θ error| "
              f"{100 * np.max(np.abs(batch.estimate.value / truth - 1)):.4f} %")
    if least_squares:
        start = time.perf_counter()
        problem, nodes = shooting_problem(*args)
        sol = solve_least_squares(problem, nodes, fit.run.estimate.value, max_evaluations=40)
        print(f"  scipy least_squares (trf, lsmr): {time.perf_counter() - start:.2f} s, "
              f"{sol.evaluations} evaluations, status {sol.status}, cost {sol.cost:.10g}, "
              f"max |θ error| {100 * np.max(np.abs(sol.theta / truth - 1)):.4f} %")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=500.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cli", action="store_true")
    parser.add_argument("--least-squares", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp) / "flight"
        settings = SimulationSettings(seed=args.seed, log_rate=args.rate)
        Simulator(load_vehicle("firefly"), settings=settings).run(
            excitation_trajectory(ExcitationSpec(duration=args.duration)), directory)
        log = directory / "pose.csv"
        print(f"firefly, {args.duration:g} s excitation logged at {args.rate:g} Hz")
        stages, total, _ = timed_estimate(log)
        print(f"first run (compiling): {total:.1f} s")
        stages, total, outcome = timed_estimate(log)
        print(f"second run ({outcome}):")
        print_stages(stages, total)
        if args.cli:
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "mavsysid", "estimate", "-q", str(log)],
                           check=False, stdout=subprocess.DEVNULL)
            print(f"  {time.perf_counter() - start:7.2f} s  whole command in a new process")
        batch_alone(log, args.least_squares)


if __name__ == "__main__":
    main()
