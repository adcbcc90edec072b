"""``mavsysid stream``: fly a trajectory file over MAVLink and record the flight.

A thin layer over `mavsysid.pipeline.stream.run_stream` (which tests call
directly): parse the options, open the session (plan checks, flight directory,
connection), fly, and print where the flight
was recorded with its tracking and rate figures. With ``--replan-budget`` the trajectory is
an opening and the rest is planned in flight
(`mavsysid.pipeline.replanned_stream.run_replanned_stream`). Exit codes: 0 flown, 2 bad input, 3
refused or aborted (one line saying why), 130 interrupted after braking and landing.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mavsysid.cli.options import (
    LINK_TIMEOUTS,
    add_link_arguments,
    add_output_folder,
    allow_negative_values,
    parse_numbers,
    require_imbalance,
    require_positive,
)
from mavsysid.errors import InputError
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.flight.mavlink_setup import signing_key_from_file
from mavsysid.pipeline.stream import StreamOutcome, run_stream

if TYPE_CHECKING:
    from mavsysid.pipeline.replanned_stream import ReplanSettings

__all__ = ["add_arguments", "format_dry_run", "format_summary", "main", "next_step"]


def format_summary(outcome: StreamOutcome, verbosity: int = 0) -> str:
    """The text printed after a flight (``verbosity`` < 0: only the flight directory)."""
    d, meta = outcome.directory, outcome.meta
    if verbosity < 0:
        return str(d)
    traj = meta["trajectory"]
    tracking = meta.get("tracking", {})
    sp = meta.get("setpoints", {})
    rates = meta.get("telemetry_rates_hz", {}).get("flight", {})
    shown = ", ".join(f"{k} {v:.1f} Hz" for k, v in rates.items()
                      if k in ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION")
                      or k.startswith("ESC_TELEMETRY"))
    lines = [f"Flew the {traj['duration']:.1f} s trajectory {traj['file']} "
             f"({meta.get('autopilot', {}).get('family', '?')}).",
             f"  pose log   {d / 'pose.csv'}  ({meta['samples']} samples)",
             f"  tlog       {d / 'flight.tlog'}",
             f"  metadata   {d / 'meta.json'}"]
    if tracking.get("rows"):
        lines.append(f"  tracking   RMS {100 * tracking['rms_m']:.1f} cm, max "
                     f"{100 * tracking['max_m']:.1f} cm")
    if "rate_hz" in sp:
        lines.append(f"  setpoints  {sp['rate_hz']:.2f} Hz achieved ({sp['sent']} sent, "
                     f"{sp['dropped']} dropped, period p99 deviation "
                     f"{1000 * sp['period_deviation_p99_s']:.2f} ms)")
    if shown:
        lines.append(f"  telemetry  {shown}")
    return "\n".join(lines)


def format_dry_run(outcome: StreamOutcome, verbosity: int = 0) -> str:
    """The text printed after ``--dry-run``: the box, the fence and what would change.

    Parameters
    ----------
    outcome : StreamOutcome
        The dry run's flight directory and its ``meta.json`` (trajectory and box in m,
        fence, and the autopilot parameters the flight would set).
    verbosity : int, optional
        -1 with ``--quiet``: only the flight directory; 0 (default) or more, one per
        ``-v``: the full text.
    """
    d, meta = outcome.directory, outcome.meta
    if verbosity < 0:
        return str(d)
    traj, fence = meta["trajectory"], meta.get("fence")
    box = traj["box"]
    lines = [f"Dry run of the {traj['duration']:.1f} s trajectory {traj['file']}: every "
             "check passed; nothing armed, no parameter changed.",
             f"  box        x {box[0]:g}..{box[3]:g}, y {box[1]:g}..{box[4]:g}, "
             f"z {box[2]:g}..{box[5]:g} m ({traj.get('box_source', '?')})"]
    if fence:
        lines.append(f"  fence      {fence['kind']} {fence['margin_m']:g} m outside the box, "
                     f"{fence['alt_max_m']:.1f} m above home")
    else:
        lines.append("  fence      none (--no-fence)")
    planned = meta.get("dry_run_parameters", {})
    for name, values in planned.items():
        lines.append(f"  would set  {name} {values['now']:g} -> {values['flight']:g}")
    if not planned:
        lines.append("  would set  no parameter")
    lines.append(f"  recorded   {d}")
    return "\n".join(lines)


def next_step(outcome: StreamOutcome, vehicle: str | None) -> str:
    """The one line printed last: the command that comes next.

    Parameters
    ----------
    outcome : StreamOutcome
        The flight (or dry run) and its ``meta.json``.
    vehicle : str or None
        ``--vehicle`` as given; None: the vehicle stored in the trajectory file (named by
        its name, which ``estimate`` finds when it is a shipped one).
    """
    if outcome.meta.get("dry_run"):
        return "next: the same command without --dry-run flies it"
    name = vehicle or outcome.meta.get("vehicle", {}).get("name", "VEHICLE")
    return f"next: mavsysid estimate {outcome.directory / 'flight.tlog'} --vehicle {name}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid stream``."""
    allow_negative_values(parser)  # "--box -2,-2,0.5,2,2,2.5"
    parser.add_argument("trajectory", type=Path, help="trajectory file (JSON) to fly")
    parser.add_argument("--connect", default="udp:127.0.0.1:14550", metavar="LINK",
                        help="udp:HOST:PORT (listen), udpout:HOST:PORT, tcp:HOST:PORT, "
                        "tcpin:HOST:PORT or a serial device[:BAUD] (default: "
                        "udp:127.0.0.1:14550)")
    parser.add_argument("--vehicle", metavar="NAME|TOML",
                        help="shipped vehicle name or TOML path (default: the configuration "
                        "stored in the trajectory file)")
    parser.add_argument("--rate", type=float, default=50.0, metavar="HZ",
                        help="setpoint rate (default: 50)")
    parser.add_argument("--telemetry-rate", type=float, default=50.0, metavar="HZ",
                        help="rate asked for pose, attitude and ESC telemetry (default: 50)")
    add_output_folder(parser, "logs", "folder for the new flight directory")
    parser.add_argument("--no-land", action="store_true",
                        help="keep hovering at the end instead of landing")
    parser.add_argument("--box", metavar="X0,Y0,Z0,X1,Y1,Z1",
                        help="the operator's flight box in m, world ENU (default: the "
                        "[flight] box of --vehicle; one of the two is required); a box stored "
                        "in the trajectory file can only narrow it")
    add_link_arguments(parser)
    parser.add_argument("--heartbeat-loss", type=float, default=3.0, metavar="S",
                        help="stop streaming after this long without a heartbeat "
                        "(default: 3 s)")
    parser.add_argument("--link-loss", type=float, default=1.0, metavar="S",
                        help="stop streaming after this long without any message from the "
                        "vehicle once its telemetry streams (default: 1 s)")
    parser.add_argument("--replan-budget", type=float, metavar="S",
                        help="re-plan in flight: TRAJECTORY is the opening; while the vehicle "
                        "holds at its end, estimate θ from it and plan the rest of S s of "
                        "flight (the opening included) from the posterior, then fly it")
    parser.add_argument("--replan-samples", type=int, metavar="N",
                        help="with --replan-budget: stop planning after N samples (the plan "
                        "then depends only on the seed)")
    parser.add_argument("--replan-time", type=float, default=10.0, metavar="S",
                        help="with --replan-budget: planning time, hovered (default: 10 s)")
    parser.add_argument("--replan-refine-steps", type=int, metavar="N",
                        help="with --replan-budget: most refinement steps (default: the "
                        "planner's; with --replan-samples keep it small, it is hovered)")
    parser.add_argument("--replan-seed", type=int, default=0, metavar="N",
                        help="with --replan-budget: sampler seed (default: 0)")
    parser.add_argument("--dry-run", action="store_true",
                        help="connect and run every check; print the box, the fence and the "
                        "parameters the flight would change; arm nothing, change nothing")
    parser.add_argument("--set-limits", action="store_true",
                        help="raise the autopilot's position-controller limits (ArduPilot "
                        "PSC_JERK_*, ANGLE_MAX, WPNAV_*, ATC_SLEW_YAW; PX4 MPC_*) that the "
                        "plan needs for the flight, and restore them afterwards (by default "
                        "a plan beyond them is refused)")


def _settings(args: argparse.Namespace) -> StreamSettings:
    require_positive(args, ("rate", "telemetry_rate", "heartbeat_loss", "link_loss",
                            *LINK_TIMEOUTS))
    require_imbalance(args)
    if args.rate > 500.0:
        raise InputError(f"--rate {args.rate:g}: at most 500 Hz")
    box = None
    if args.box is not None:
        box = parse_numbers(args.box, 6, "--box", "x_min,y_min,z_min,x_max,y_max,z_max")
    key = None if args.signing_key is None else signing_key_from_file(args.signing_key)
    return StreamSettings(
        connect=args.connect, rate=args.rate, telemetry_rate=args.telemetry_rate,
        land=not args.no_land, box=box, signing_key=key, speedup=args.speedup,
        heartbeat_timeout=args.heartbeat_timeout, heartbeat_loss=args.heartbeat_loss,
        position_timeout=args.position_timeout, max_tracking_error=args.max_tracking_error,
        max_motor_imbalance=args.max_motor_imbalance,
        link_loss=args.link_loss, prearm_timeout=args.prearm_timeout,
        log_dir=args.log_dir, lockstep=args.lockstep, fence=not args.no_fence,
        set_limits=args.set_limits, dry_run=args.dry_run,
        download_log=not args.no_log_download)


def _replan_settings(args: argparse.Namespace) -> ReplanSettings | None:
    if args.replan_budget is None:
        return None
    require_positive(args, ("replan_budget", "replan_time"))
    for option in ("replan_samples", "replan_refine_steps"):
        value = getattr(args, option)
        if value is not None and value < (1 if option == "replan_samples" else 0):
            raise InputError(f"--{option.replace('_', '-')} {value}: expected a count "
                             f"(at least {1 if option == 'replan_samples' else 0})")
    # Only a re-planned flight loads the estimator and the planner.
    from mavsysid.pipeline.replanned_stream import FEEDBACK_HEADROOM, ReplanSettings
    from mavsysid.planner.settings import PlannerSettings

    time = float("inf") if args.replan_samples is not None else args.replan_time
    planner = PlannerSettings(planning_time=time, max_samples=args.replan_samples,
                              seed=args.replan_seed, rotor_headroom=FEEDBACK_HEADROOM)
    if args.replan_refine_steps is not None:
        planner = replace(planner, refine_steps=args.replan_refine_steps)
    return ReplanSettings(budget=args.replan_budget, planner=planner)


def _segment_lines(meta: dict[str, Any]) -> list[str]:
    lines = []
    for record in meta.get("segments", []):
        if "duration" not in record:
            continue
        extra = "" if "planning_s" not in record else (
            f" (held {record['hold_s']:.1f} s: estimate {record['estimation_s']:.1f} s, "
            f"planning {record['planning_s']:.1f} s)")
        lines.append(f"  segment    {record['kind']} {record['duration']:.1f} s{extra}")
    return lines


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    settings = _settings(args)
    replan = _replan_settings(args)
    verbose = args.verbosity >= 0

    def say(text: str) -> None:
        if verbose:
            print(f"mavsysid stream: {text}", file=sys.stderr, flush=True)

    if settings.dry_run and replan is not None:
        raise InputError("--dry-run flies nothing: it takes no --replan-budget")
    if replan is None:
        outcome = run_stream(args.trajectory, settings, args.vehicle, say, progress=verbose)
        print(format_dry_run(outcome, args.verbosity) if settings.dry_run
              else format_summary(outcome, args.verbosity))
        if args.verbosity >= 0:
            print(next_step(outcome, args.vehicle))
        return 0
    from mavsysid.pipeline.replanned_stream import run_replanned_stream

    outcome = run_replanned_stream(args.trajectory, settings, replan, args.vehicle, say,
                                   progress=verbose)
    print("\n".join([format_summary(outcome, args.verbosity)]
                    + ([] if args.verbosity < 0 else [*_segment_lines(outcome.meta),
                                                      next_step(outcome, args.vehicle)])))
    return 0
