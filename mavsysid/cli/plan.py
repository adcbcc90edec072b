"""``mavsysid plan``: plan a maximally informative calibration flight.

A thin layer over `run_plan` (which tests call directly): check the request, run the
information-gathering planner (or the paper's random baseline) with a progress bar,
print a summary and write the trajectory file, and on request the sampled setpoints and
a Rerun recording. Nothing is written when planning fails.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mavsysid.errors import ConfigError, InputError, JobFailedError
from mavsysid.formats.trajectory_file import write_setpoints_csv, write_trajectory
from mavsysid.planner.feasibility import check_rotor_headroom
from mavsysid.planner.results import PlannerSettings, PlanProgress, PlanResult
from mavsysid.vehicle.config import GRAVITY, PARAMETER_NAMES, VehicleConfig, load_vehicle

__all__ = [
    "DEFAULT_BOX",
    "MIN_BOX_SIDE",
    "add_arguments",
    "check_request",
    "format_summary",
    "main",
    "parse_numbers",
    "run_plan",
]

#: Shortest side of a flight box, m, whatever the vehicle.
MIN_BOX_SIDE = 0.5
#: The planner's default flight box as the ``--box`` text of the commands.
DEFAULT_BOX = ",".join(f"{v:g}" for v in PlannerSettings.box)
_DEFAULT_TIME = 30.0
_KIND_LABELS = {"dopt": "information-gathering planner", "random": "random baseline"}
_UNITS = {"c_T": "N/(rad/s)²", "c_D": "s/m", "c_M": "N·m/(rad/s)²",
          "j_x": "kg·m²", "j_y": "kg·m²", "j_z": "kg·m²"}

ProgressCallback = Callable[[PlanProgress], None]


def parse_numbers(text: str, count: int, option: str, names: str) -> tuple[float, ...]:
    """``count`` finite comma-separated numbers from an option value.

    Raises
    ------
    InputError
        One line naming the option and the expected ``names`` (e.g. "x,y,z,yaw").
    """
    parts = [p.strip() for p in text.split(",")]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InputError(f"{option} {text!r}: expected {count} comma-separated finite "
                         f"numbers {names}")
    return values


def _clearance(config: VehicleConfig) -> float:
    """Distance from the centre of gravity to the farthest rotor hub in the x-y plane, m."""
    return float(np.max(np.linalg.norm(config.rotor_positions[:, :2], axis=1)))


def _check_box(settings: PlannerSettings, config: VehicleConfig) -> None:
    box = np.asarray(settings.box, dtype=float)
    shown = ",".join(f"{v:g}" for v in box)
    if box.shape != (6,) or not np.all(np.isfinite(box)):
        raise InputError(f"--box {shown}: expected 6 finite numbers "
                         "x_min,y_min,z_min,x_max,y_max,z_max")
    side = box[3:] - box[:3]
    need = max(MIN_BOX_SIDE, 2.0 * _clearance(config))
    for axis, length in zip("xyz", side, strict=True):
        if length <= 0.0:
            raise InputError(f"--box {shown}: {axis}_min must be below {axis}_max")
        if length < need:
            raise InputError(f"--box {shown}: the {axis} side is {length:g} m; the "
                             f"{config.name} needs at least {need:.2g} m")
    start = settings.start_pose
    if start.shape != (4,) or not np.all(np.isfinite(start)):
        raise InputError("--start: expected 4 finite numbers x,y,z,yaw")
    # The start hover must leave the rotors inside the box, not only the centre of gravity.
    margin = float(np.min(np.concatenate([start[:3] - box[:3], box[3:] - start[:3]])))
    if margin < _clearance(config):
        raise InputError(
            f"--start {','.join(f'{v:g}' for v in start)}: the {config.name} must start at "
            f"least {_clearance(config):.2g} m inside --box {shown}, got {margin:.2g} m")


def _check_hover(config: VehicleConfig) -> None:
    """Refuse limits within which the vehicle cannot hover (one line naming the key)."""
    limits = config.limits
    if limits.thrust_min_ratio >= 1.0:
        raise ConfigError(
            f"{config.source}: [limits].thrust_min_ratio: below 1 so that the vehicle can "
            f"hover (T_min < m g), got {limits.thrust_min_ratio!r}")
    if limits.thrust_max_ratio <= 1.0:
        raise ConfigError(
            f"{config.source}: [limits].thrust_max_ratio: above 1 so that the vehicle can "
            f"climb out of hover (T_max > m g), got {limits.thrust_max_ratio!r}")
    idle_thrust = config.rotor_count * config.parameters.c_T * limits.rotor_speed_min**2
    if idle_thrust >= config.mass * GRAVITY:
        raise ConfigError(
            f"{config.source}: [limits].rotor_speed_min: a speed at which the rotors lift "
            f"less than m g = {config.mass * GRAVITY:.4g} N, got {limits.rotor_speed_min!r} "
            f"rad/s giving {idle_thrust:.4g} N")


def check_request(config: VehicleConfig, settings: PlannerSettings) -> None:
    """Refuse a planning request that cannot make sense, before planning starts.

    Raises
    ------
    InputError
        A malformed or too small box, a start outside it, a budget or planning time
        ≤ 0, no limit on planning at all, a sample count ≤ 0 or a negative seed; or
        (`ConfigError`) limits the vehicle cannot hover within. One line each.
    """
    if not (math.isfinite(settings.budget) and settings.budget > 0.0):
        raise InputError(f"--budget {settings.budget:g}: expected a flight time > 0 s")
    if settings.max_samples is not None and settings.max_samples < 1:
        raise InputError(f"--samples {settings.max_samples}: expected at least 1 sample")
    if not settings.planning_time > 0.0:
        raise InputError(f"--time {settings.planning_time:g}: expected a planning time > 0 s "
                         "(or --samples N to stop after N samples)")
    if math.isinf(settings.planning_time) and settings.max_samples is None:
        raise InputError("--time: an unlimited planning time needs --samples N")
    if settings.seed < 0:
        raise InputError(f"--seed {settings.seed}: expected an integer ≥ 0")
    if settings.refine_steps < 0:
        raise InputError(f"--refine-steps {settings.refine_steps}: expected an integer ≥ 0")
    if not (settings.measurement_rate > 0.0 and settings.prior_relative_sigma > 0.0):
        raise InputError("planner settings: measurement rate and prior σ must be positive")
    _check_box(settings, config)
    _check_hover(config)
    check_rotor_headroom(config, settings.rotor_headroom, "--rotor-headroom")


@contextmanager
def _progress_bar(settings: PlannerSettings) -> Iterator[ProgressCallback]:
    """A tqdm bar on stderr fed by the planner's progress reports (off when not a tty)."""
    from tqdm import tqdm  # only the console script needs it

    by_samples = settings.max_samples is not None
    total = settings.max_samples if by_samples else settings.planning_time
    # disable=None: tqdm stays quiet when stderr is not a terminal (logs, pipes, CI).
    with tqdm(total=total, unit="sample" if by_samples else "s", file=sys.stderr,
              disable=None, leave=False, dynamic_ncols=True,
              bar_format=None if by_samples else "{l_bar}{bar}| {n:.0f}/{total:.0f} s{postfix}",
              ) as bar:

        def report(progress: PlanProgress) -> None:
            done = progress.samples if by_samples else min(progress.elapsed, float(total))
            bar.update(done - bar.n)
            best = "—" if progress.best_dopt is None else f"{progress.best_dopt:.3g}"
            # A dict keeps this order; keyword arguments would be sorted by name.
            bar.set_postfix({"vertices": progress.vertices, "beliefs": progress.beliefs,
                             "D-opt": best, "elapsed": f"{progress.elapsed:.1f} s"},
                            refresh=False)

        yield report


def run_plan(
    vehicle: str | Path | VehicleConfig, settings: PlannerSettings, random: bool = False,
    progress: bool | ProgressCallback = True,
) -> PlanResult:
    """Check a planning request and plan.

    Parameters
    ----------
    vehicle : str, Path or VehicleConfig
        Shipped vehicle name, TOML path, or a loaded configuration.
    settings : PlannerSettings
        Budget, planning time and/or sample count, box, start, seed.
    random : bool
        Use the paper's random baseline instead of the information-gathering planner.
    progress : bool or callable
        True: a progress bar on stderr (when it is a terminal); False: none; a callable:
        called with each `PlanProgress`.

    Raises
    ------
    InputError
        See `check_request`, and unknown or malformed vehicles.
    JobFailedError
        No feasible trajectory was found; the message says how long was searched and how
        large the graph grew.
    """
    config = vehicle if isinstance(vehicle, VehicleConfig) else load_vehicle(vehicle)
    check_request(config, settings)
    if random:
        from mavsysid.planner.baseline import plan_random as planner
    else:
        from mavsysid.planner.rrbt import plan as planner
    last: list[PlanProgress] = []

    def track(report: ProgressCallback | None) -> ProgressCallback:
        def callback(p: PlanProgress) -> None:
            last[:] = [p]
            if report is not None:
                report(p)
        return callback

    try:
        if progress is True:
            with _progress_bar(settings) as bar:
                return planner(config, settings, progress=track(bar))
        return planner(config, settings, progress=track(progress or None))
    except JobFailedError as error:
        text = str(error)
        if text.startswith("no feasible") or not last:
            raise
        p = last[0]
        raise JobFailedError(f"no feasible trajectory found in {p.elapsed:.1f} s "
                             f"({p.vertices} vertices, {p.edges} edges): {text}") from None


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
        rows.append([name, _UNITS[name], f"{config.theta[j]:.3e}",
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
    # Lets "--box -2,-2,0.5,2,2,2.5" through: Python < 3.13 takes any argument that starts
    # with "-" and is not a plain number for an option (3.13 uses this very pattern).
    parser._negative_number_matcher = re.compile(r"-\.?\d")  # type: ignore[attr-defined]
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
    """PlannerSettings from the command line (numbers checked by `check_request`)."""
    names = "x_min,y_min,z_min,x_max,y_max,z_max"
    box = parse_numbers(args.box, 6, "--box", names)
    start = None if args.start is None else parse_numbers(args.start, 4, "--start", "x,y,z,yaw")
    time = args.time
    if time is None:
        time = math.inf if args.samples is not None else _DEFAULT_TIME
    elif time == 0.0 and args.samples is not None:
        time = math.inf
    return PlannerSettings(budget=args.budget, planning_time=time, max_samples=args.samples,
                           box=box, start=start, seed=args.seed,  # type: ignore[arg-type]
                           refine_steps=args.refine_steps, rotor_headroom=args.rotor_headroom)


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
