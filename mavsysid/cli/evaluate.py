"""``mavsysid evaluate``: the paper's repeatability experiment (thin layer over
`mavsysid.experiments.evaluate_job.run_evaluation`, which tests call directly)."""

from __future__ import annotations

import argparse
from pathlib import Path

from mavsysid.cli.options import (
    DEFAULT_BOX,
    add_output_folder,
    allow_negative_values,
    parse_numbers,
)
from mavsysid.errors import InputError
from mavsysid.experiments.evaluate_job import EvaluationRun, make_specs, run_evaluation, table_notes
from mavsysid.planner.settings import PlannerSettings

__all__ = ["add_arguments", "format_summary", "main"]


def format_summary(run: EvaluationRun) -> str:
    """What the command prints: the table, the notes of table.md and the files."""
    s = run.summary
    lines = [f"{s.experiments} experiments in {run.out} ({run.ran} run now, "
             f"{s.experiments - run.ran} reused).", "", run.table.rstrip()]
    for note in table_notes(run.headline, run.saturating or {}, run.off_path or {}):
        lines += ["", note]
    lines.append("")
    lines += [f"  {name:<16} {path}" for name, path in run.files.items()]
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid evaluate``."""
    allow_negative_values(parser)
    parser.add_argument("--n", type=int, default=20, help="experiments (default: 20)")
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path: the truth (default: firefly)")
    parser.add_argument("--budget", type=float, default=30.0, metavar="S",
                        help="flight-time budget, s (default: 30)")
    parser.add_argument("--time", type=float, metavar="S",
                        help="planning time per plan, s (default: 30; not with --samples)")
    parser.add_argument("--samples", type=int, metavar="N",
                        help="stop each plan after N samples, with no time limit: the results "
                        "then depend only on the seeds")
    parser.add_argument("--refine-steps", type=int, metavar="N",
                        help="most refinement steps of the planner (default: the planner's)")
    parser.add_argument("--rotor-headroom", type=float, default=PlannerSettings.rotor_headroom,
                        metavar="F", help="fraction of the rotor n² range the plans leave "
                        f"free at each end (default: {PlannerSettings.rotor_headroom:g})")
    parser.add_argument("--controller-model", default="truth", metavar="{truth,prior}",
                        help="θ the simulated flight controller is tuned with: the truth "
                        "(default; the paper's RotorS controller, a tuned autopilot) or the "
                        "±50 %% guess the flight was planned with")
    parser.add_argument("--box", default=DEFAULT_BOX, metavar="X0,Y0,Z0,X1,Y1,Z1",
                        help=f"flight volume in m, world ENU (default: {DEFAULT_BOX})")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of experiment 0; experiment i uses seed + i (default: 0)")
    parser.add_argument("--iterations", type=int, default=1,
                        help="plan–fly–estimate rounds per experiment (default: 1)")
    add_output_folder(parser, "evaluation", "output folder; finished experiments there are "
                      "reused", ("--out",))
    parser.add_argument("--executor", choices=("local", "dask"), default="local",
                        help="local process pool (default) or an existing Dask cluster")
    parser.add_argument("--workers", type=int, default=1,
                        help="local processes (default: 1, the paper's single process)")
    parser.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                        help="Dask scheduler address, with --executor dask")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="also write a Rerun recording of the results")
    parser.add_argument("--no-png", action="store_true", help="do not write the PNG plots")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    box = parse_numbers(args.box, 6, "--box", "x_min,y_min,z_min,x_max,y_max,z_max")
    if args.workers < 1:
        raise InputError(f"--workers {args.workers}: expected at least 1")
    if args.time is not None and args.samples is not None:
        raise InputError(f"--time {args.time:g} with --samples {args.samples}: evaluate stops "
                         "each plan by one of them; give --time or --samples")
    time = 30.0 if args.time is None else args.time
    specs = make_specs(args.n, args.vehicle, args.budget, time, args.samples, box,
                       args.seed, args.iterations, args.refine_steps, args.rotor_headroom,
                       args.controller_model)
    run = run_evaluation(args.log_dir, specs, args.executor, args.workers, args.scheduler,
                         args.rrd, png=not args.no_png, progress=args.verbosity >= 0)
    print(format_summary(run))
    return 0
