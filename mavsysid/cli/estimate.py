"""``mavsysid estimate``: θ with uncertainties from a flight log.

A thin layer over `mavsysid.estimation.estimate_job.run_estimate` (which tests call
directly: read the log, run the filter and the refinement): print the table, write the
JSON, the updated vehicle config and the Rerun recording on request. The vehicle
config's model effects (``[effects.NAME]``) are part of the model; their parameters are
fitted with θ (or held with ``--fixed-effects``), reported, and written back by
``--update-vehicle``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mavsysid.cli.options import add_log_arguments
from mavsysid.estimation.estimate_job import run_estimate
from mavsysid.estimation.estimator import EstimatorSettings
from mavsysid.estimation.report import format_table, updated_vehicle, write_estimate_json
from mavsysid.vehicle.config import save_vehicle

__all__ = ["add_arguments", "main"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid estimate``."""
    add_log_arguments(parser)
    parser.add_argument("-o", "--output", type=Path, metavar="JSON",
                        help="write the estimate as JSON")
    parser.add_argument("--update-vehicle", type=Path, metavar="TOML",
                        help="write a copy of the vehicle config with the estimates")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="write a Rerun recording of the estimation")
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
    parser.add_argument("--fixed-effects", action="store_true",
                        help="hold the vehicle config's model effects ([effects.NAME]) at "
                        "their values instead of fitting their parameters with θ")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    settings = EstimatorSettings(prior_relative_sigma=args.prior_sigma,
                                 refine=not args.no_refine, fit_effects=not args.fixed_effects)
    run = run_estimate(args.log, args.vehicle, args.pose, args.time_offset, settings)
    if args.output is not None:
        write_estimate_json(args.output, run.result, run.config, args.log)
    if args.update_vehicle is not None:
        save_vehicle(updated_vehicle(run.config, run.result), args.update_vehicle)
    if args.rrd is not None:
        from mavsysid.estimation.recording import write_estimation_rrd  # rerun loads slowly

        write_estimation_rrd(args.rrd, run.result, run.flight)
    if args.verbosity >= 0:
        print(format_table(run.result, run.config, str(args.log)))
    written = [f"{what} {path}" for what, path in (("estimate", args.output),
               ("vehicle", args.update_vehicle), ("recording", args.rrd)) if path is not None]
    if written:
        print("wrote " + ", ".join(written))
    return 0
