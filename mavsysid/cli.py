"""The ``mavsysid`` console script: argument parsing, dispatch and exit codes.

Exit codes (DESIGN.md): 0 success, 2 bad input or usage (one line, no traceback), 3 the
job could not be done, 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from mavsysid import __version__, diagnose, estimate, offline, plan, sim, stream
from vehicle.errors import MavsysidError

__all__ = ["build_parser", "main"]

EXIT_INTERRUPTED = 130

#: Subcommands still to come, with the one-line summary shown in --help.
_PLANNED = {
    "evaluate": "run the paper's repeatability experiment",
}


#: Built commands: (name, module with add_arguments/main, --help line, description).
_COMMANDS = (
    ("demo", offline, "the whole experiment on the simulated vehicle",
     "Run the demonstration on the simulated reference vehicle. For now: simulate it flying "
     "the built-in excitation trajectory and write a pose log."),
    ("simulate", offline, "fly the offline simulator and write a pose log",
     "Simulate a vehicle flying the built-in excitation trajectory (physics ≥ 500 Hz, "
     "geometric controller, motor lag, motion-capture noise) and write pose.csv, truth.csv "
     "and meta.json into a new flight directory."),
    ("estimate", estimate, "estimate θ = [c_T, c_D, c_M, j_x, j_y, j_z] from a log",
     "Estimate the thrust, drag and moment coefficients and the inertia, with uncertainties, "
     "from a flight log (pose.csv, .tlog, .ulg or .bin): a parameter EKF, then a "
     "process-noise fit and a batch MAP refinement."),
    ("diagnose", diagnose, "find, name and fit what the model still gets wrong",
     "Replay the identified model along the logged rotor speeds, compare it with the "
     "accelerations of the smoothed pose, and report where they disagree; name the "
     "physical effect(s) that explain the difference (forward selection on BIC over a "
     "catalogue of nine), fit them with confidence intervals, and show how much the gap "
     "shrinks on held-out data (the last 30 %% of the flight)."),
    ("plan", plan, "plan a maximally informative calibration flight",
     "Plan a calibration flight that minimises the predicted parameter uncertainty "
     "(D-optimality) within a flight-time budget and a flight box, using the vehicle's "
     "nominal parameters as the model; or, with --random, the paper's random baseline. "
     "Writes the trajectory file, and on request sampled setpoints and a Rerun recording."),
    ("sim", sim, "run a simulated MAVLink vehicle endpoint",
     "Run a simulated multirotor that speaks MAVLink 2 like ArduPilot Copter (or PX4 with "
     "--autopilot px4): heartbeat, telemetry at settable rates, parameters, modes, arming, "
     "takeoff and landing, GUIDED/OFFBOARD setpoints, with the offline simulator's physics "
     "in real time (or --speedup K faster), optional signing and a ground-truth log."),
    ("stream", stream, "stream a trajectory to a vehicle over MAVLink and record the flight",
     "Fly a trajectory file with a MAVLink vehicle (ArduPilot Copter or PX4, real or "
     "`mavsysid sim`): check the plan and the vehicle, take off, stream position, velocity, "
     "acceleration and yaw setpoints at a fixed rate, land, and record flight.tlog, pose.csv "
     "and meta.json into a new flight directory."),
)


def _not_implemented(command: str) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        print(f"mavsysid {command}: not implemented yet", file=sys.stderr)
        return 2

    run.accepts_any_arguments = True  # type: ignore[attr-defined]
    return run


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the console script."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", dest="verbosity", action="count",
                        default=argparse.SUPPRESS, help="print more detail")
    common.add_argument("-q", "--quiet", dest="quiet", action="store_true",
                        default=argparse.SUPPRESS, help="print only the essential result")

    parser = argparse.ArgumentParser(
        prog="mavsysid", parents=[common],
        description="Plan, fly, estimate and diagnose multirotor system-identification flights.",
    )
    parser.add_argument("--version", action="version", version=f"mavsysid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    for name, module, summary, description in _COMMANDS:
        command = sub.add_parser(name, parents=[common], help=summary, description=description)
        module.add_arguments(command)
        command.set_defaults(run=module.main)

    for command, summary in _PLANNED.items():
        p = sub.add_parser(command, parents=[common], help=f"{summary} (not implemented yet)",
                           description=f"{summary[0].upper()}{summary[1:]}. Not implemented yet.")
        p.set_defaults(run=_not_implemented(command))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mavsysid`` console script; returns the exit code."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown and not getattr(args.run, "accepts_any_arguments", False):
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    verbosity = getattr(args, "verbosity", 0)
    args.verbosity = -1 if getattr(args, "quiet", False) else verbosity
    try:
        return args.run(args)
    except MavsysidError as error:
        print(f"mavsysid {args.command}: error: {error}", file=sys.stderr)
        return error.exit_code
    except KeyboardInterrupt:
        print(f"mavsysid {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
