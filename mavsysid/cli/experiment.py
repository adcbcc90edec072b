"""``mavsysid experiment``: the whole experiment on a real autopilot in one command.

A thin layer over `mavsysid.pipeline.autopilot_experiment.run_autopilot_experiment`:
read the position-controller limits from the vehicle on ``--connect``, plan within them,
fly the plan, estimate θ from the flight's ``flight.tlog``, and print the plan, the flight
and the estimate (``--report DIR``: its figures and one-page HTML, as ``estimate
--report``). Everything is kept in the flight directory. ``--dry-run`` plans and runs every
check of the flight on the vehicle, arming nothing. Exit codes: 0 estimated (or checked),
2 bad input, 3 refused at any stage (one line naming it), 130 interrupted after braking
and landing.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from mavsysid.cli.options import (
    LINK_TIMEOUTS,
    add_link_arguments,
    add_noise_argument,
    allow_negative_values,
    parse_numbers,
    require_imbalance,
    require_positive,
)
from mavsysid.cli.stream import format_dry_run
from mavsysid.cli.stream import format_summary as flight_summary
from mavsysid.errors import InputError
from mavsysid.estimation import (
    EstimatorSettings,
    format_table,
    noise_from_flights,
)
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.flight.mavlink_setup import signing_key_from_file
from mavsysid.pipeline.autopilot_experiment import ExperimentOutcome, run_autopilot_experiment
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

__all__ = ["add_arguments", "format_report", "main", "next_step"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid experiment``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The ``experiment`` subcommand's parser; its options are added to it in place.
    """
    allow_negative_values(parser)  # "--box -2,-2,0.5,2,2,2.5"
    parser.add_argument("--connect", required=True, metavar="LINK",
                        help="the vehicle: udp:HOST:PORT (listen), udpout:HOST:PORT, "
                        "tcp:HOST:PORT or a serial device[:BAUD], as `stream --connect`")
    parser.add_argument("--vehicle", required=True, metavar="NAME|TOML",
                        help="shipped vehicle name or TOML path: the plan's model and the "
                        "estimate's prior")
    parser.add_argument("--budget", type=float, default=20.0, metavar="S",
                        help="flight time, s, the final stop included (default: 20)")
    parser.add_argument("--box", metavar="X0,Y0,Z0,X1,Y1,Z1",
                        help="the operator's flight box in m, world ENU, for the plan and "
                        "the flight (default: the [flight] box of --vehicle; one of the two "
                        "is required)")
    parser.add_argument("--time", type=float, metavar="S",
                        help=f"planning time, wall s (default: {PlannerSettings.planning_time:g}, "
                        "or no limit with --samples)")
    parser.add_argument("--samples", type=int, metavar="N",
                        help="stop planning after N samples: the plan then depends only on "
                        "the seed")
    parser.add_argument("--refine-steps", type=int, default=PlannerSettings.refine_steps,
                        metavar="N", help="most steps refining the search's best flight "
                        f"(default: {PlannerSettings.refine_steps}; keep it small with "
                        "--samples)")
    parser.add_argument("--seed", type=int, default=0, help="planner seed (default: 0)")
    parser.add_argument("--log-dir", type=Path, default=Path("logs"), metavar="DIR",
                        help="where the flight directory is created (default: ./logs)")
    parser.add_argument("--autopilot-model", action="store_true",
                        help="also read the autopilot's position- and attitude-controller "
                        "parameters and plan on the flight its closed loop is predicted to "
                        "fly from the setpoints (default: the setpoints count as flown "
                        "exactly)")
    add_noise_argument(parser)
    add_link_arguments(parser)
    parser.add_argument("--prior-sigma", type=float,
                        default=EstimatorSettings.prior_relative_sigma, metavar="REL",
                        help="the estimate's prior σ relative to the vehicle file's θ "
                        f"(default: {EstimatorSettings.prior_relative_sigma:g})")
    parser.add_argument("--report", type=Path, metavar="DIR",
                        help="write the estimate's figures (PNG), history.csv and a one-page "
                        "HTML report (index.html) into DIR, as `estimate --report`")
    parser.add_argument("--dry-run", action="store_true",
                        help="read the limits, plan, connect and run every check of the "
                        "flight; print the plan, the box, the fence and the parameters the "
                        "flight would change; arm nothing, change nothing, estimate nothing")


def _operator_box(args: argparse.Namespace) -> tuple[float, ...]:
    """``--box``, else the vehicle file's ``[flight] box``: nothing flies without one."""
    if args.box is not None:
        return parse_numbers(args.box, 6, "--box", "x_min,y_min,z_min,x_max,y_max,z_max")
    box = load_vehicle(args.vehicle).box
    if box is None:
        raise InputError(f"--vehicle {args.vehicle}: no [flight] box in the vehicle file; give "
                         "the operator's box with --box x_min,y_min,z_min,x_max,y_max,z_max")
    return tuple(box)


def _settings(args: argparse.Namespace) -> tuple[PlannerSettings, StreamSettings]:
    require_positive(args, (*LINK_TIMEOUTS, "prior_sigma"))
    require_imbalance(args)
    if args.dry_run and args.report is not None:
        raise InputError("--dry-run estimates nothing: it takes no --report")
    box = _operator_box(args)
    time = args.time
    if time is None:
        time = math.inf if args.samples is not None else PlannerSettings.planning_time
    planner = PlannerSettings(budget=args.budget, planning_time=time, max_samples=args.samples,
                              box=box, seed=args.seed,  # type: ignore[arg-type]
                              refine_steps=args.refine_steps)
    key = None if args.signing_key is None else signing_key_from_file(args.signing_key)
    stream = StreamSettings(connect=args.connect, box=box, signing_key=key,
                            speedup=args.speedup, heartbeat_timeout=args.heartbeat_timeout,
                            position_timeout=args.position_timeout,
                            prearm_timeout=args.prearm_timeout, log_dir=args.log_dir,
                            fence=not args.no_fence, lockstep=args.lockstep,
                            max_tracking_error=args.max_tracking_error,
                            max_motor_imbalance=args.max_motor_imbalance,
                            dry_run=args.dry_run, download_log=not args.no_log_download)
    return planner, stream


def format_report(outcome: ExperimentOutcome, verbosity: int = 0) -> str:
    """The text printed after an experiment (``verbosity`` < 0: the estimate file alone).

    Parameters
    ----------
    outcome : ExperimentOutcome
        The finished experiment: its plan, the autopilot limits it was planned within,
        the flight and the estimate with the path of the estimate file.
    verbosity : int, optional
        -1 with ``--quiet``: only the estimate file's path; 0 (default) or more, one per
        ``-v``: the plan, the flight summary and the estimate table.
    """
    if verbosity < 0:
        return str(outcome.estimate_file or outcome.flight.directory)
    plan = outcome.plan
    lines = [f"Planned a {plan.trajectory.duration:.1f} s flight of the "
             f"{plan.settings.budget:g} s budget within the limits of {outcome.limits}; "
             f"predicted D-opt {plan.predicted_dopt:.3g}.",
             f"  trajectory {outcome.trajectory}"]
    if plan.shortfall:
        lines.append(f"  warning    {plan.shortfall}")
    run = outcome.estimate
    if run is None:  # a dry run
        return "\n".join([*lines, format_dry_run(outcome.flight, verbosity)])
    lines += [flight_summary(outcome.flight, verbosity), "",
              format_table(run.result, run.config, str(run.flight.source)),
              f"wrote estimate {outcome.estimate_file}"]
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line: the options of `add_arguments` and ``verbosity``
        (-1 quiet, 0 default, more with ``-v``).
    """
    planner, stream = _settings(args)
    verbose = args.verbosity >= 0

    def say(text: str) -> None:
        if verbose or text.startswith("warning:"):
            print(f"mavsysid experiment: {text}", file=sys.stderr, flush=True)

    noise = None if args.noise_from is None else noise_from_flights(args.noise_from)[0]
    outcome = run_autopilot_experiment(
        args.vehicle, planner, stream, EstimatorSettings(prior_relative_sigma=args.prior_sigma),
        say, progress=verbose, autopilot_model=args.autopilot_model, noise=noise)
    if args.report is not None and outcome.estimate is not None:
        from mavsysid.estimation import write_estimate_report  # matplotlib: slow

        run = outcome.estimate
        write_estimate_report(args.report, run.result, run.flight, run.config,
                              str(run.flight.source))
    print(format_report(outcome, args.verbosity))
    if args.verbosity >= 0:
        if args.report is not None:
            print(f"wrote report {args.report}")
        print(next_step(outcome, args.vehicle))
    return 0


def next_step(outcome: ExperimentOutcome, vehicle: str) -> str:
    """The one line printed last: the command that comes next.

    Parameters
    ----------
    outcome : ExperimentOutcome
        The finished experiment (or dry run).
    vehicle : str
        ``--vehicle`` as given.
    """
    if outcome.estimate_file is None:
        return "next: the same command without --dry-run flies it"
    log = (outcome.flight.directory / "flight.tlog" if outcome.estimate is None
           else outcome.estimate.flight.source)
    return (f"next: mavsysid diagnose {log} --vehicle {vehicle} --estimate "
            f"{outcome.estimate_file}")
