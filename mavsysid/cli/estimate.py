"""``mavsysid estimate``: θ with uncertainties from a flight log.

A thin layer over `mavsysid.pipeline.estimate.run_estimate` (which tests call
directly: read the log, run the filter and the refinement): print the table, write the
JSON, the updated vehicle config and the Rerun recording on request. The vehicle
config's model effects (``[effects.NAME]``) are part of the model; their parameters are
fitted with θ (or held with ``--fixed-effects``), reported, and written back by
``--update-vehicle``. ``--auto-effects`` lets the diagnosis name the effects the log
shows and estimates θ again with them
(`mavsysid.pipeline.auto_effects.run_estimate_with_named_effects`). ``--report DIR``
writes figures, the estimate over time and a one-page HTML; ``--history CSV`` the estimate
over time alone. While it works, the stages are shown on stderr (on a terminal, or always
with ``-v``; never with ``-q``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from mavsysid.cli.options import add_log_arguments, add_window_arguments
from mavsysid.estimation import (
    EstimatorSettings,
    ParameterEstimate,
    StageLog,
    describe_log_kinds,
    format_table,
    progress_wanted,
    report_stage,
    stage_listener,
    updated_vehicle,
    write_estimate_json,
    write_history_csv,
)
from mavsysid.pipeline.estimate import EstimateRun, run_estimate
from mavsysid.pipeline.simulate import read_truth
from mavsysid.vehicle.config import PARAMETER_NAMES, save_vehicle

__all__ = ["DESCRIPTION", "add_arguments", "format_truth", "main"]

#: What ``mavsysid estimate --help`` says the command does.
DESCRIPTION = (
    "Estimate the thrust, drag and moment coefficients and the inertia, with uncertainties, "
    f"from a flight log ({describe_log_kinds()}), parameter by parameter. The force and "
    "torque balance of the flight (its pose differentiated and its rotor speeds, band, "
    "smoothing and rotor-to-pose delay chosen from the flight, Newey–West σ) answers; the "
    "paper's parameter EKF with its batch refinement checks it and stands where it agrees "
    "and is the more precise. What the flight does not determine keeps the vehicle file's "
    "value and is said so; a flight neither determines anything of is refused.")

#: ``--truth`` alone: the truth recorded next to the log (a `mavsysid simulate` flight).
_OWN_TRUTH = "next to the log"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid estimate``."""
    add_log_arguments(parser, describe_log_kinds())
    add_window_arguments(parser)
    parser.add_argument("--truth", nargs="?", const=_OWN_TRUTH, metavar="PATH",
                        help="compare with a simulator's true θ: its meta.json or the "
                        "directory holding it (`mavsysid sim --truth-log DIR`); alone: the "
                        "log's own directory (`mavsysid simulate`); prints each parameter's "
                        "error and z-score")
    parser.add_argument("-o", "--output", type=Path, metavar="JSON",
                        help="write the estimate as JSON")
    parser.add_argument("--update-vehicle", type=Path, metavar="TOML",
                        help="write a copy of the vehicle config with the estimates")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="write a Rerun recording of the estimation")
    parser.add_argument("--report", type=Path, metavar="DIR",
                        help="write figures (PNG), the estimate over time (history.csv) and "
                        "a one-page HTML report (index.html) into DIR")
    parser.add_argument("--history", type=Path, metavar="CSV",
                        help="write the filter's estimate over time as CSV (t, each "
                        "parameter and its σ, NIS)")
    parser.add_argument("--pose", type=Path, metavar="CSV",
                        help="external motion-capture pose log to merge with the log")
    parser.add_argument("--time-offset", type=float, metavar="S",
                        help="clock offset of --pose relative to the log (default: found "
                        "by cross-correlation)")
    parser.add_argument("--prior-sigma", type=float, default=0.5, metavar="REL",
                        help="prior σ of each parameter relative to the config's value "
                        "(default: 0.5)")
    parser.add_argument("--no-refine", action="store_true",
                        help="report the filter only (skip noise fit and batch refinement)")
    parser.add_argument("--filter-imu", action="store_true",
                        help="the parameter filter reads the flight's IMU too, its biases "
                        "and offset as states (the force and torque balance reads it "
                        "either way; 2–3× slower, no batch refinement)")
    parser.add_argument("--fixed-effects", action="store_true",
                        help="hold the vehicle config's model effects ([effects.NAME]) at "
                        "their values instead of fitting their parameters with θ")
    parser.add_argument("--auto-effects", action="store_true",
                        help="diagnose the flight and, if it names effects the model lacks "
                        "(wind, motor lag …), estimate θ again with them fitted (slower)")


def format_truth(final: ParameterEstimate, truth: np.ndarray) -> str:
    """Each parameter against the simulator's truth: error and z = error / σ.

    Parameters
    ----------
    final : ParameterEstimate
        The estimate of θ = [c_T, c_D, c_M, j_x, j_y, j_z] with its covariance, SI units.
    truth : ndarray, shape (6,)
        The simulator's true θ in the same order and units (`read_truth`).
    """
    lines = ["Against the truth", "  parameter   estimate          σ       true   error %       z"]
    for j, name in enumerate(PARAMETER_NAMES):
        value, sigma, true = float(final.value[j]), float(final.sigma[j]), float(truth[j])
        z = (value - true) / sigma if sigma > 0.0 else float("inf")
        lines.append(f"  {name:<9} {value:10.3e} {sigma:10.2e} {true:10.3e} "
                     f"{100.0 * (value - true) / abs(true):+9.2f} {z:+7.2f}")
    worst = float(np.max(np.abs((final.value[:6] - truth) / final.sigma[:6])))
    lines.append(f"  largest |z| {worst:.2f}" + ("" if worst <= 3.0 else
                                                "  (beyond 3: the σ does not cover the truth)"))
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    settings = EstimatorSettings(prior_relative_sigma=args.prior_sigma,
                                 refine=not args.no_refine, fit_effects=not args.fixed_effects,
                                 filter_imu=args.filter_imu)
    truth = None if args.truth is None else read_truth(
        args.log.parent if args.truth == _OWN_TRUTH else Path(args.truth))
    show = progress_wanted(args.verbosity, sys.stderr)
    with stage_listener(StageLog("mavsysid estimate", sys.stderr) if show else None):
        report_stage(f"reading {args.log}")
        job = run_estimate
        if args.auto_effects:  # the diagnosis stack (statsmodels) loads only when asked for
            from mavsysid.pipeline.auto_effects import run_estimate_with_named_effects

            job = run_estimate_with_named_effects
        run = job(args.log, args.vehicle, args.pose, args.time_offset, settings,
                  start=args.start, end=args.end)
        _write_extras(args, run)
    if args.output is not None:
        write_estimate_json(args.output, run.result, run.config, args.log)
    if args.update_vehicle is not None:
        save_vehicle(updated_vehicle(run.config, run.result), args.update_vehicle)
    if args.rrd is not None:
        from mavsysid.estimation import (
            write_estimation_rrd,
        )

        write_estimation_rrd(args.rrd, run.result, run.flight)
    if args.verbosity >= 0:
        print(format_table(run.result, run.config, str(args.log)))
    if truth is not None:
        print(format_truth(run.result.final, truth))
    written = [f"{what} {path}" for what, path in (("estimate", args.output),
               ("vehicle", args.update_vehicle), ("recording", args.rrd),
               ("history", args.history), ("report", args.report)) if path is not None]
    if written:
        print("wrote " + ", ".join(written))
    return 0


def _write_extras(args: argparse.Namespace, run: EstimateRun) -> None:
    """The estimate over time and the report folder, when asked for."""
    if args.history is not None:
        write_history_csv(args.history, run.result.history)
    if args.report is not None:
        report_stage(f"writing the report into {args.report}")
        from mavsysid.estimation import (
            write_estimate_report,
        )

        write_estimate_report(args.report, run.result, run.flight, run.config, str(args.log))
