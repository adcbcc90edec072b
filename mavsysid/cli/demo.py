"""``mavsysid demo``: the whole experiment on the simulated vehicle, end to end.

Plan, fly over MAVLink against the simulated vehicle, estimate and diagnose, in one run
folder: a thin layer over `mavsysid.pipeline.demo.run_demo` (which tests call
directly), printing the one-screen summary.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from mavsysid.discrepancy.diagnosis import Diagnosis
from mavsysid.pipeline.demo import DemoResult, DemoSettings, run_demo
from mavsysid.vehicle.config import PARAMETER_NAMES

__all__ = ["add_arguments", "diagnosis_lines", "format_summary", "main"]


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
