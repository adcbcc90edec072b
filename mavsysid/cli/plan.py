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
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mavsysid.cli.options import (
    DEFAULT_BOX,
    add_noise_argument,
    allow_negative_values,
    parse_numbers,
)
from mavsysid.errors import InputError
from mavsysid.formats.setpoints_csv import write_setpoints_csv
from mavsysid.pipeline.plan import (
    SATURATION_WARNING,
    PlanPreview,
    describe_noise,
    for_noise_met,
    preview_plan,
    read_autopilot,
    run_plan,
    with_margins,
)
from mavsysid.planner.plan_file import write_trajectory
from mavsysid.planner.plan_result import BUSY_CORE_SHARE, PlanResult
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, load_vehicle
from mavsysid.vehicle.parameters import MAX_RELATIVE_SIGMA

__all__ = ["DEFAULT_ROTOR_HEADROOM", "add_arguments", "format_preview", "format_summary", "main",
           "next_step", "saturation_warning"]

#: `plan`'s rotor headroom unless --rotor-headroom says otherwise: with it the README's plan
#: command predicts ≤ 1 % rotor saturation on every shipped vehicle (docs/plan-preview.md).
DEFAULT_ROTOR_HEADROOM = 0.15

_DEFAULT_TIME = 30.0
_KIND_LABELS = {"dopt": "information-gathering planner", "random": "random baseline"}


def format_summary(result: PlanResult, written: dict[str, Path], verbosity: int = 0,
                   set_aside: tuple[str, ...] = ()) -> str:
    """The text printed after planning (``verbosity`` < 0: only the trajectory file).

    Parameters
    ----------
    result : PlanResult
    written : dict of str to Path
        What was written, by kind ("trajectory", "setpoints", "recording").
    verbosity : int
        -1 quiet, 0 default, more with ``-v``.
    set_aside : tuple of str
        Parameters the earlier flights' estimates set aside though their filters resolved
        them (`mavsysid.estimation.read_set_aside`): expected so again.
    """
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
    rows = [["parameter", "unit", "nominal", "prior σ", "final σ", "σ/|θ| %", "expected"]]
    for j, name in enumerate(PARAMETER_NAMES):
        nominal = abs(float(config.theta[j]))
        rows.append([name, PARAMETER_UNITS[name], f"{config.theta[j]:.3e}",
                     f"{s.prior_relative_sigma * nominal:.2e}", f"{final[j]:.2e}",
                     f"{100.0 * final[j] / nominal:.3g}" if nominal else "n/a",
                     _expected(final[j], nominal, name in set_aside)])
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines += ["    " + "  ".join(c.ljust(w) if i < 2 else c.rjust(w)
                                 for i, (c, w) in enumerate(zip(r, widths, strict=True)))
              for r in rows]
    if set_aside:
        lines += [f"  set aside  {', '.join(set_aside)}: resolved by the filter on the "
                  "--noise-from flights but set aside by their estimates",
                  "             (filter and force-torque balance disagreed: a model mismatch "
                  "`mavsysid diagnose` names); expect the same here"]
    first = stats.time_to_first_solution
    busy = ""
    if stats.elapsed > 0.0 and 0.0 < stats.cpu_time < BUSY_CORE_SHARE * stats.elapsed:
        busy = f" ({100 * stats.cpu_time / stats.elapsed:.0f} % of a core: a busy machine)"
    lines.append(f"  planner    {stats.samples} samples, {stats.vertices} vertices, "
                 f"{stats.edges} edges, {stats.beliefs} beliefs in {stats.elapsed:.1f} s{busy}; "
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
                        help=f"planning time in s (default: {_DEFAULT_TIME:g}; with --samples "
                        "whichever comes first, 0: no limit)")
    parser.add_argument("--samples", type=int, metavar="N",
                        help="stop after N samples, with no time limit unless --time: the "
                        "result then depends only on the seed")
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
                        default=DEFAULT_ROTOR_HEADROOM,
                        help="fraction of the rotor n² range left free at each end, for the "
                        "autopilot and for a vehicle whose θ differs from the prior's "
                        f"(default: {DEFAULT_ROTOR_HEADROOM:g})")
    for name, what in (("body-rate", "body rate"), ("yaw-acceleration", "yaw acceleration"),
                       ("thrust", "thrust above hover")):
        parser.add_argument(f"--{name}-margin", type=float, default=0.0, metavar="F",
                            help=f"share of the vehicle's {what} limit left unused (default: "
                            "0; the demo plans with 0.3)")
    parser.add_argument("--no-preview", action="store_true",
                        help="skip the offline flight of the plan that predicts its rotor "
                        "saturation")
    parser.add_argument("--rotor-confidence", type=float, metavar="Z",
                        default=PlannerSettings.rotor_confidence,
                        help="chance-constrained rotor check: each rotor limit holds at the "
                        "prior θ plus Z times its first-order spread under the prior (a normal "
                        "quantile, e.g. 1.645: 95 %% per rotor and sample; default: "
                        f"{PlannerSettings.rotor_confidence:g}, at the prior θ only)")
    parser.add_argument("--connect", metavar="LINK",
                        help="plan within the position-controller limits of the autopilot "
                        "that will fly it, read live from the vehicle on this MAVLink link, "
                        "as `stream --connect` takes it (tcp:HOST:PORT, udp:HOST:PORT, "
                        "udpout:HOST:PORT, a serial device[:BAUD]); nothing is changed on it. "
                        "ArduPilot WPNAV_*, PSC_JERK_*, PSC_ANGLE_MAX, ANGLE_MAX, "
                        "ATC_SLEW_YAW, ATC_RATE_Y_MAX, ATC_ACCEL_*_MAX or PX4 MPC_* are used, "
                        "absent ones limit nothing; the plan then passes `stream`'s limit "
                        "check against the same values")
    parser.add_argument("--autopilot-limits", metavar="FILE|LINK",
                        help="the same limits from a parameter dump FILE of 'NAME VALUE' lines "
                        "(ArduPilot .parm / MAVProxy 'param save', Mission Planner "
                        "'NAME,VALUE', QGroundControl .params; # comments), in the "
                        "parameters' own units; or, as --connect, a LINK")
    parser.add_argument("--autopilot-model", action="store_true",
                        help="with --connect or --autopilot-limits: also read the autopilot's "
                        "position- and attitude-controller parameters (ArduCopter PSC_*, ATC_*, "
                        "MOT_THST_HOVER; PX4 MPC_*, MC_*; absent ones at their stock "
                        "defaults) and plan on the flight its closed loop is predicted to fly "
                        "from the setpoints (default: the setpoints count as flown exactly)")
    parser.add_argument("--signing-key", type=Path, metavar="FILE",
                        help="MAVLink 2 signing for --connect LINK: a file holding the "
                        "passphrase")
    add_noise_argument(parser)
    parser.add_argument("--random", action="store_true",
                        help="the paper's random baseline instead of the informative planner")
    parser.add_argument("-o", "--output", type=Path, default=Path("trajectory.json"),
                        metavar="JSON", help="trajectory file (default: trajectory.json)")
    parser.add_argument("--csv", type=Path, metavar="FILE",
                        help="also write setpoints t,x,y,z,vx,vy,vz,ax,ay,az,yaw,yaw_rate "
                        "at 100 Hz")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="also write a Rerun recording of the plan")


def _expected(sigma: float, nominal: float, set_aside: bool = False) -> str:
    """What ``estimate`` is predicted to say of a parameter: determined where its σ is
    within `MAX_RELATIVE_SIGMA` of its value (``estimate``'s rule), unless earlier
    flights' estimates set it aside for a model mismatch."""
    if not nominal:
        return "n/a"
    if sigma > MAX_RELATIVE_SIGMA * nominal:
        return "not determined"
    return "set aside before" if set_aside else "determined"


def _settings(args: argparse.Namespace, say: Callable[[str], None]) -> PlannerSettings:
    """PlannerSettings from the command line (checked by `run_plan`)."""
    names = "x_min,y_min,z_min,x_max,y_max,z_max"
    box = parse_numbers(args.box, 6, "--box", names)
    start = None if args.start is None else parse_numbers(args.start, 4, "--start", "x,y,z,yaw")
    time = args.time
    if time is None:
        time = math.inf if args.samples is not None else _DEFAULT_TIME
    elif time == 0.0 and args.samples is not None:
        time = math.inf
    limits = loop = None
    given = _limits_source(args)
    if given is not None:
        key = None
        if args.signing_key is not None:
            from mavsysid.flight.mavlink_setup import signing_key_from_file

            key = signing_key_from_file(args.signing_key)
        envelope = read_autopilot(given, key, say=say, loop=args.autopilot_model)
        limits, loop = envelope.limits, envelope.loop
        say(f"planning within the autopilot limits read from {envelope.source}")
    elif args.signing_key is not None:
        raise InputError("--signing-key: only with --connect LINK")
    elif args.autopilot_model:
        raise InputError("--autopilot-model: only with --connect LINK or --autopilot-limits FILE")
    return PlannerSettings(budget=args.budget, planning_time=time, max_samples=args.samples,
                           box=box, start=start, seed=args.seed,  # type: ignore[arg-type]
                           refine_steps=args.refine_steps, rotor_headroom=args.rotor_headroom,
                           autopilot_limits=limits, rotor_confidence=args.rotor_confidence,
                           autopilot=loop)


def _limits_source(args: argparse.Namespace) -> str | None:
    """Where the autopilot's limits come from: ``--connect LINK`` or ``--autopilot-limits
    FILE|LINK`` (one of them), else None."""
    if args.connect is not None and args.autopilot_limits is not None:
        raise InputError("--connect and --autopilot-limits both name the autopilot's limits: "
                         "give one")
    if args.connect is not None:
        from mavsysid.flight.mavlink_setup import parse_connect

        parse_connect(args.connect)  # a link; a parameter dump is --autopilot-limits FILE
        return str(args.connect)
    return args.autopilot_limits


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    def say(text: str) -> None:
        if args.verbosity >= 0:
            print(f"mavsysid plan: {text}", file=sys.stderr, flush=True)

    settings = _settings(args, say)
    set_aside: tuple[str, ...] = ()
    outputs = {"trajectory": args.output, "setpoints": args.csv, "recording": args.rrd}
    written = {k: Path(v) for k, v in outputs.items() if v is not None}
    for path in written.values():
        if path.is_dir():
            raise InputError(f"{path}: is a directory; expected a file name to write")
    config = with_margins(load_vehicle(args.vehicle), args.body_rate_margin,
                          args.yaw_acceleration_margin, args.thrust_margin)
    if args.noise_from is not None:
        from mavsysid.estimation import noise_from_flights  # the estimator loads slowly

        met, set_aside = noise_from_flights(args.noise_from)
        config, settings = for_noise_met(config, settings, met)
        where = ", ".join(str(p) for p in args.noise_from)
        say(f"planning for the noise the estimator met on {where}"
            f"{' (median)' if len(args.noise_from) > 1 else ''}: {describe_noise(met)}")
    result = run_plan(config, settings, random=args.random, progress=args.verbosity >= 0,
                      say=say)
    if result.shortfall:  # even with -q: the flight is not the one asked for
        print(f"mavsysid plan: warning: {result.shortfall}", file=sys.stderr, flush=True)
    write_trajectory(args.output, result)
    if args.csv is not None:
        write_setpoints_csv(args.csv, result.trajectory)
    if args.rrd is not None:
        from mavsysid.planner.recording import write_plan_rrd  # rerun loads slowly

        write_plan_rrd(args.rrd, result)
    print(format_summary(result, written, args.verbosity, set_aside))
    if not args.no_preview:
        if args.verbosity >= 0:
            print("mavsysid plan: flying the plan on the offline simulator (nominal "
                  f"{config.name}) to predict rotor saturation", file=sys.stderr, flush=True)
        preview = preview_plan(result.trajectory, load_vehicle(args.vehicle))
        if args.verbosity >= 0:
            print(format_preview(preview))
        if (warning := saturation_warning(preview)) is not None:
            print(f"mavsysid plan: warning: {warning}", file=sys.stderr)
    if args.verbosity >= 0:
        print(next_step(args.output, settings.box, _limits_link(args)))
    return 0


def _limits_link(args: argparse.Namespace) -> str | None:
    """The link the limits were read from (``--connect``, or a link given as
    ``--autopilot-limits``), else None."""
    if args.connect is not None:
        return str(args.connect)
    given = args.autopilot_limits
    if given is None or Path(given).is_file():
        return None
    return str(given)


def next_step(trajectory: Path, box: tuple[float, ...], link: str | None) -> str:
    """The one line printed last: how to fly the plan.

    Parameters
    ----------
    trajectory : Path
        The trajectory file written.
    box : tuple of 6 float
        The box planned in, m ([x_min, y_min, z_min, x_max, y_max, z_max]), offered as the
        operator's ``--box``.
    link : str or None
        The vehicle's link when the limits were read from it.
    """
    shown = ",".join(f"{v:g}" for v in box)
    connect = f" --connect {link}" if link is not None else " --connect LINK"
    return f"next: mavsysid stream {trajectory}{connect} --box {shown}"


def saturation_warning(preview: PlanPreview) -> str | None:
    """One line when the predicted rotor saturation is above `SATURATION_WARNING`.

    Parameters
    ----------
    preview : PlanPreview
        What the plan asks of the vehicle (`preview_plan`); its ``saturation`` is the
        share (0 to 1) of simulated control ticks with a rotor command clipped.
    """
    if preview.saturation <= SATURATION_WARNING:
        return None
    return (f"rotors predicted saturated in {100 * preview.saturation:.1f} % of control "
            f"ticks (above {100 * SATURATION_WARNING:g} %): the autopilot has no room to "
            "correct; raise --rotor-headroom or the margins")


def format_preview(preview: PlanPreview) -> str:
    """The plan's peaks and its predicted rotor saturation, two lines.

    Parameters
    ----------
    preview : PlanPreview
        What the plan asks of the vehicle (`preview_plan`): peak speed (m/s), tilt (rad),
        body rate (rad/s) and thrust (m g), saturated share of control ticks and largest
        tracking error (m).
    """
    return (f"  peaks      speed {preview.speed:.2f} m/s, tilt "
            f"{np.degrees(preview.tilt):.1f}°, body rate {preview.body_rate:.2f} rad/s, "
            f"thrust {preview.thrust:.2f} m g\n"
            f"  preview    rotors saturated in {100 * preview.saturation:.1f} % of control "
            f"ticks on the offline simulator (nominal θ, motor lag); tracking within "
            f"{100 * preview.tracking_max:.1f} cm")
