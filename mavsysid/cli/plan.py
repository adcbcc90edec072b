"""``mavsysid plan``: plan a maximally informative calibration flight.

A thin layer over `mavsysid.pipeline.plan.run_plan`, which checks the request
(`mavsysid.planner.plan_request`) and runs the information-gathering planner (or the
paper's random baseline) with a progress bar: parse the options, plan, write the
trajectory file (and on request the sampled setpoints and a Rerun recording) and print a
summary. Nothing is written when planning fails.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from mavsysid.cli.options import DEFAULT_BOX, allow_negative_values, parse_numbers
from mavsysid.errors import InputError
from mavsysid.formats.setpoints_csv import write_setpoints_csv
from mavsysid.pipeline.plan import run_plan
from mavsysid.planner.plan_file import write_trajectory
from mavsysid.planner.results import PlannerSettings, PlanResult
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS

__all__ = ["add_arguments", "format_summary", "main"]

_DEFAULT_TIME = 30.0
_KIND_LABELS = {"dopt": "information-gathering planner", "random": "random baseline"}


def format_summary(result: PlanResult, written: dict[str, Path], verbosity: int = 0) -> str:
    """The text printed after planning (``verbosity`` < 0: only the trajectory file)."""
    if verbosity < 0:
        return str(written["trajectory"])
    s, stats, config = result.settings, result.stats, result.config
    kind = _KIND_LABELS.get(result.kind, result.kind)
    start = ", ".join(f"{v:g}" for v in s.start_pose[:3])
    lines = [
        f"Planned a {result.trajectory.duration:.1f} s calibration flight for {config.name} "
        f"({kind}, seed {s.seed}, {result.trajectory.durations.size} segments).",
        f"  box        [{', '.join(f'{v:g}' for v in s.box[:3])}] to "
        f"[{', '.join(f'{v:g}' for v in s.box[3:])}] m; start [{start}] m, "
        f"yaw {s.start_pose[3]:g} rad",
        f"  predicted  D-opt {result.predicted_dopt:.4g} (det Σθ^(1/6), SI)",
    ]
    final = np.sqrt(np.clip(np.diag(np.asarray(result.predicted_covariance)), 0.0, None))
    rows = [["parameter", "unit", "nominal", "prior σ", "final σ", "σ/|θ| %"]]
    for j, name in enumerate(PARAMETER_NAMES):
        nominal = abs(float(config.theta[j]))
        rows.append([name, PARAMETER_UNITS[name], f"{config.theta[j]:.3e}",
                     f"{s.prior_relative_sigma * nominal:.2e}", f"{final[j]:.2e}",
                     f"{100.0 * final[j] / nominal:.3g}" if nominal else "n/a"])
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines += ["    " + "  ".join(c.ljust(w) if i < 2 else c.rjust(w)
                                 for i, (c, w) in enumerate(zip(r, widths, strict=True)))
              for r in rows]
    first = stats.time_to_first_solution
    lines.append(f"  planner    {stats.samples} samples, {stats.vertices} vertices, "
                 f"{stats.edges} edges, {stats.beliefs} beliefs in {stats.elapsed:.1f} s; "
                 f"first solution after {'—' if first is None else f'{first:.1f} s'}")
    if stats.refine_steps:
        lines.append(f"  refined    {stats.refine_accepted} of {stats.refine_steps} "
                     "perturbations of the best flight kept")
    if verbosity > 0:
        lines.append(f"             {stats.edges_attempted} connections tried "
                     f"({stats.edge_time:.1f} s), {stats.beliefs_propagated} belief "
                     f"propagations ({stats.propagation_time:.1f} s)")
    lines.append("  wrote      " + ", ".join(f"{k} {v}" for k, v in written.items()))
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid plan``."""
    allow_negative_values(parser)  # "--box -2,-2,0.5,2,2,2.5"
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path (default: firefly)")
    parser.add_argument("--budget", type=float, default=30.0, metavar="S",
                        help="longest flight, stopping included, in s (default: 30)")
    parser.add_argument("--time", type=float, metavar="S",
                        help=f"planning time in s (default: {_DEFAULT_TIME:g}, or no limit "
                        "with --samples; 0 with --samples: no limit)")
    parser.add_argument("--samples", type=int, metavar="N",
                        help="stop after N samples: the result then depends only on the seed")
    parser.add_argument("--box", default=DEFAULT_BOX, metavar="X0,Y0,Z0,X1,Y1,Z1",
                        help=f"flight volume in m, world ENU (default: {DEFAULT_BOX})")
    parser.add_argument("--start", metavar="X,Y,Z,YAW",
                        help="start hover, m and rad (default: box centre, yaw 0)")
    parser.add_argument("--seed", type=int, default=0, help="sampler seed (default: 0)")
    parser.add_argument("--refine-steps", type=int, default=PlannerSettings.refine_steps,
                        metavar="N", help="most steps refining the search's best flight in "
                        f"the last {100 * PlannerSettings.refine_share:.0f}%% of the planning time "
                        f"(default: {PlannerSettings.refine_steps}; 0: paper's search only)")
    parser.add_argument("--rotor-headroom", type=float, metavar="F",
                        default=PlannerSettings.rotor_headroom,
                        help="fraction of the rotor n² range left free at each end, for the "
                        "autopilot and for a vehicle whose θ differs from the prior's "
                        f"(default: {PlannerSettings.rotor_headroom:g})")
    parser.add_argument("--rotor-confidence", type=float, metavar="Z",
                        default=PlannerSettings.rotor_confidence,
                        help="chance-constrained rotor check: each rotor limit holds at the "
                        "prior θ plus Z times its first-order spread under the prior (a normal "
                        "quantile, e.g. 1.645: 95 %% per rotor and sample; default: "
                        f"{PlannerSettings.rotor_confidence:g}, at the prior θ only)")
    parser.add_argument("--autopilot-limits", type=Path, metavar="FILE",
                        help="plan within the position-controller limits of the autopilot "
                        "that will fly it: a parameter dump of 'NAME VALUE' lines (ArduPilot "
                        ".parm / MAVProxy 'param save', Mission Planner 'NAME,VALUE', "
                        "QGroundControl .params; # comments), in the parameters' own units; "
                        "ArduPilot WPNAV_*, PSC_JERK_*, PSC_ANGLE_MAX, ANGLE_MAX, ATC_SLEW_YAW, "
                        "ATC_RATE_Y_MAX, ATC_ACCEL_*_MAX or PX4 MPC_* are used, absent ones "
                        "limit nothing; the plan then passes `stream`'s limit check against "
                        "the same values")
    parser.add_argument("--random", action="store_true",
                        help="the paper's random baseline instead of the informative planner")
    parser.add_argument("-o", "--output", type=Path, default=Path("trajectory.json"),
                        metavar="JSON", help="trajectory file (default: trajectory.json)")
    parser.add_argument("--csv", type=Path, metavar="FILE",
                        help="also write setpoints t,x,y,z,vx,vy,vz,ax,ay,az,yaw,yaw_rate "
                        "at 100 Hz")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="also write a Rerun recording of the plan")


def _settings(args: argparse.Namespace) -> PlannerSettings:
    """PlannerSettings from the command line (checked by `run_plan`)."""
    names = "x_min,y_min,z_min,x_max,y_max,z_max"
    box = parse_numbers(args.box, 6, "--box", names)
    start = None if args.start is None else parse_numbers(args.start, 4, "--start", "x,y,z,yaw")
    time = args.time
    if time is None:
        time = math.inf if args.samples is not None else _DEFAULT_TIME
    elif time == 0.0 and args.samples is not None:
        time = math.inf
    limits = None
    if args.autopilot_limits is not None:
        # The ground station's limit tables (and the MAVLink set-up they import) only here.
        from mavsysid.flight.ground.autopilot_limits import limits_from_parameters
        from mavsysid.formats.parameter_file import read_parameter_file

        values = read_parameter_file(args.autopilot_limits)
        limits = limits_from_parameters(values, str(args.autopilot_limits))[1]
    return PlannerSettings(budget=args.budget, planning_time=time, max_samples=args.samples,
                           box=box, start=start, seed=args.seed,  # type: ignore[arg-type]
                           refine_steps=args.refine_steps, rotor_headroom=args.rotor_headroom,
                           autopilot_limits=limits, rotor_confidence=args.rotor_confidence)


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    settings = _settings(args)
    outputs = {"trajectory": args.output, "setpoints": args.csv, "recording": args.rrd}
    written = {k: Path(v) for k, v in outputs.items() if v is not None}
    for path in written.values():
        if path.is_dir():
            raise InputError(f"{path}: is a directory; expected a file name to write")
    result = run_plan(args.vehicle, settings, random=args.random,
                      progress=args.verbosity >= 0)
    write_trajectory(args.output, result)
    if args.csv is not None:
        write_setpoints_csv(args.csv, result.trajectory)
    if args.rrd is not None:
        from mavsysid.planner.recording import write_plan_rrd  # rerun loads slowly

        write_plan_rrd(args.rrd, result)
    print(format_summary(result, written, args.verbosity))
    return 0
