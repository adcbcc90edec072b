"""The ``mavsysid`` console script: argument parsing, dispatch and exit codes.

Exit codes (DESIGN.md): 0 success, 2 bad input or usage (one line, no traceback), 3 the
job could not be done, 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from mavsysid import __version__, demo, diagnose, estimate, evaluate, offline, plan, sim, stream
from vehicle.errors import MavsysidError

__all__ = ["build_parser", "main"]

EXIT_INTERRUPTED = 130

#: Built commands: (name, module with add_arguments/main, --help line, description).
_COMMANDS = (
    ("demo", demo, "the whole experiment on the simulated vehicle",
     "Run the whole experiment on the simulated reference vehicle: plan an informative "
     "flight for the nominal model, start the simulated MAVLink vehicle (whose true θ is "
     "hidden from the model), stream the plan to it and record the flight, estimate θ; with "
     "--iterations, re-plan with the updated model and fly again. Prints planned vs achieved "
     "σ and the estimates against the simulator's truth."),
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
    ("evaluate", evaluate, "run the paper's repeatability experiment",
     "The paper's evaluation: N experiments, each drawing the unknown parameters ±50 % "
     "around the truth, planning a D-optimal and a random flight with the same budget, "
     "flying both in the simulator and running the EKF. Writes runs.csv, the paper's table "
     "(table.md) and plots; finished experiments are reused when run again. Runs on a "
     "local process pool or an existing Dask cluster."),
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

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mavsysid`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
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
