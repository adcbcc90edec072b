"""``mavsysid diagnose``: find, name and fit what the model still gets wrong.

A thin layer over `mavsysid.pipeline.diagnose.run_diagnose` (which tests call
directly: read the log and the estimate, run
`mavsysid.discrepancy.diagnosis.diagnose_flight`): print the report, write the JSON, the
augmented vehicle config and the Rerun recording on request.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mavsysid.cli.options import add_log_arguments, add_window_arguments
from mavsysid.discrepancy.diagnosis import MASS_NOTE, DiagnosisSettings
from mavsysid.discrepancy.report import (
    augmented_vehicle,
    format_diagnosis,
    format_reestimate,
    write_diagnosis_json,
)
from mavsysid.estimation import (
    StageLog,
    describe_log_kinds,
    progress_wanted,
    report_stage,
    stage_listener,
)
from mavsysid.pipeline.diagnose import reestimate_comparison, run_diagnose
from mavsysid.vehicle.config import save_vehicle
from mavsysid.vehicle.model_effects import EFFECTS

__all__ = ["DESCRIPTION", "add_arguments", "main"]

#: What ``mavsysid diagnose --help`` says the command does.
DESCRIPTION = (
    "Replay the identified model along the logged rotor speeds, compare it with the "
    "accelerations of the smoothed pose, and report where they disagree; name the physical "
    "effect(s) that explain the difference (forward selection on BIC over the catalogue: "
    f"{', '.join(EFFECTS)}), fit them with confidence intervals, and show how much the gap "
    "shrinks on held-out data (the end of the flight, --holdout).")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid diagnose``."""
    add_log_arguments(parser, describe_log_kinds())
    add_window_arguments(parser)
    parser.add_argument("--estimate", type=Path, metavar="JSON",
                        help="estimate.json of this flight: the θ to replay (default: the "
                        "vehicle config's)")
    parser.add_argument("-o", "--output", type=Path, metavar="JSON",
                        help="write the diagnosis as JSON")
    parser.add_argument("--write-config", type=Path, metavar="TOML",
                        help="write the vehicle config with the named effects added")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="write a Rerun recording of the diagnosis")
    parser.add_argument("--report", type=Path, metavar="DIR",
                        help="write figures (PNG) and a one-page HTML report (index.html) "
                        "into DIR")
    parser.add_argument("--holdout", type=float, default=0.3, metavar="FRACTION",
                        help="end of the flight kept out of all fitting (default: 0.3)")
    parser.add_argument("--reestimate", action="store_true",
                        help="also run the estimator (EKF) with the augmented model: θ and "
                        "the effects' parameters estimated together")
    parser.add_argument("--mass-check", action="store_true",
                        help="say whether a wrong mass can be detected, and exit")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    if args.mass_check:
        print(f"mass check: {MASS_NOTE}.")
        return 0
    show = progress_wanted(args.verbosity, sys.stderr)
    with stage_listener(StageLog("mavsysid diagnose", sys.stderr) if show else None):
        report_stage(f"reading {args.log}")
        run = run_diagnose(args.log, args.vehicle, args.estimate,
                           DiagnosisSettings(holdout=args.holdout), start=args.start,
                           end=args.end)
    if args.output is not None:
        write_diagnosis_json(args.output, run.diagnosis, run.config, str(args.log))
    if args.write_config is not None:
        save_vehicle(augmented_vehicle(run.config, run.diagnosis), args.write_config)
    if args.rrd is not None:
        from mavsysid.discrepancy.recording import write_diagnosis_rrd  # rerun loads slowly

        write_diagnosis_rrd(args.rrd, run.diagnosis, str(args.log), run.flight)
    if args.report is not None:
        from mavsysid.discrepancy.report_figures import write_diagnosis_report  # matplotlib

        write_diagnosis_report(args.report, run.diagnosis, run.flight, run.config,
                               str(args.log))
    if args.verbosity >= 0:
        print(format_diagnosis(run.diagnosis, run.config, str(args.log)))
    if args.reestimate and run.diagnosis.effects:
        before, after = reestimate_comparison(run)
        if args.verbosity >= 0:
            print(format_reestimate(before, after))
    written = [f"{what} {path}" for what, path in (("diagnosis", args.output),
               ("vehicle", args.write_config), ("recording", args.rrd),
               ("report", args.report)) if path is not None]
    if written:
        print("wrote " + ", ".join(written))
    return 0
