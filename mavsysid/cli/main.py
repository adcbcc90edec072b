"""The ``mavsysid`` console script: argument parsing, dispatch and exit codes.

Exit codes (docs/architecture.md): 0 success, 2 bad input or usage (one line, no traceback), 3 the
job could not be done, 130 interrupted. Anything unexpected is an internal error: one line and
exit 1, the traceback only with ``MAVSYSID_DEBUG=1``. Warnings of mavsysid's own kinds print as
one line too.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
import warnings
from collections.abc import Callable, Sequence
from typing import TextIO

from mavsysid import __version__
from mavsysid.errors import InputError, JobFailedError, MavsysidError

__all__ = [
    "COMMAND_NAMES", "DEBUG_ENV", "EXIT_CODES", "EXIT_INTERNAL", "EXIT_INTERRUPTED",
    "build_parser", "exit_code", "help_text", "main",
]

EXIT_INTERRUPTED = 130
#: Exit code of an unexpected exception (a bug: reported in one line, traceback on request).
EXIT_INTERNAL = 1
#: Environment variable that, set to 1, prints the traceback of an internal error.
DEBUG_ENV = "MAVSYSID_DEBUG"

#: Exit code of each error type; an error takes the code of the first type in its method
#: resolution order found here (`ConfigError` and `LogFormatError` are `InputError`s).
#: 1 is for a `MavsysidError` of no more specific kind (argparse exits with 2 on bad usage
#: by itself).
EXIT_CODES: dict[type[MavsysidError], int] = {
    MavsysidError: 1,
    InputError: 2,
    JobFailedError: 3,
}

#: Built commands: (name, module with add_arguments/main, --help line, description).
#: Modules are imported only for the command being run: the estimation and diagnosis
#: stack takes seconds to import, which a ``sim`` or ``stream`` start should not pay.
_COMMANDS = (
    ("demo", "mavsysid.cli.demo", "the whole experiment on the simulated vehicle",
     "Run the whole experiment on the simulated reference vehicle: plan an informative "
     "flight for the nominal model, start the simulated MAVLink vehicle (whose true θ is "
     "hidden from the model), stream the plan to it and record the flight, estimate θ; with "
     "--iterations, re-plan with the updated model and fly again. Prints planned vs achieved "
     "σ and the estimates against the simulator's truth."),
    ("experiment", "mavsysid.cli.experiment",
     "the whole experiment on a real autopilot: plan, fly, estimate",
     "Run the whole experiment on a real autopilot (ArduPilot Copter or PX4, e.g. ArduCopter "
     "SITL): read its position-controller limits over --connect, plan an informative flight "
     "within them, stream it and record the flight, estimate θ from the flight's own "
     "flight.tlog (rotor speeds from its ESC telemetry or its motor outputs through the "
     "vehicle file's motor curve), and print the plan, the flight and the estimate."),
    ("simulate", "mavsysid.cli.simulate", "fly the offline simulator and write a pose log",
     "Simulate a vehicle flying the built-in excitation trajectory (physics ≥ 500 Hz, "
     "geometric controller, motor lag, motion-capture noise) and write pose.csv, truth.csv "
     "and meta.json into a new flight directory."),
    ("estimate", "mavsysid.cli.estimate", "estimate θ = [c_T, c_D, c_M, j_x, j_y, j_z] from a log",
     "Estimate the thrust, drag and moment coefficients and the inertia, with uncertainties, "
     "from a flight log, parameter by parameter."),
    ("diagnose", "mavsysid.cli.diagnose", "find, name and fit what the model still gets wrong",
     "Replay the identified model along the logged rotor speeds, compare it with the "
     "accelerations of the smoothed pose, and report where they disagree; name the "
     "physical effect(s) that explain the difference, fit them with confidence intervals, "
     "and show how much the gap shrinks on held-out data."),
    ("plan", "mavsysid.cli.plan", "plan a maximally informative calibration flight",
     "Plan a calibration flight that minimises the predicted parameter uncertainty "
     "(D-optimality) within a flight-time budget and a flight box, using the vehicle's "
     "nominal parameters as the model; or, with --random, the paper's random baseline. "
     "Writes the trajectory file, and on request sampled setpoints and a Rerun recording."),
    ("evaluate", "mavsysid.cli.evaluate", "run the paper's repeatability experiment",
     "The paper's evaluation: N experiments, each drawing the unknown parameters ±50 % "
     "around the truth, planning a D-optimal and a random flight with the same budget, "
     "flying both in the simulator and running the EKF. Writes runs.csv, the paper's table "
     "(table.md) and plots; finished experiments are reused when run again. Runs on a "
     "local process pool or an existing Dask cluster."),
    ("sim", "mavsysid.cli.sim", "run a simulated MAVLink vehicle endpoint",
     "Run a simulated multirotor that speaks MAVLink 2 like ArduPilot Copter (or PX4 with "
     "--autopilot px4): heartbeat, telemetry at settable rates, parameters, modes, arming, "
     "takeoff and landing, GUIDED/OFFBOARD setpoints, with the offline simulator's physics "
     "in real time (or --speedup K faster), optional signing and a ground-truth log."),
    ("stream", "mavsysid.cli.stream",
     "stream a trajectory to a vehicle over MAVLink and record the flight",
     "Fly a trajectory file with a MAVLink vehicle (ArduPilot Copter or PX4, real or "
     "`mavsysid sim`): check the plan and the vehicle, take off, stream position, velocity, "
     "acceleration and yaw setpoints at a fixed rate, land, and record flight.tlog, pose.csv "
     "and meta.json into a new flight directory."),
    ("restore", "mavsysid.cli.restore", "put back the parameters a flight changed",
     "Put back on the vehicle every autopilot parameter (fence, timeouts, limits) that a "
     "flight's meta.json lists as changed, with its value before the flight, and read them "
     "back: for a streamer that could not (killed, crashed, link lost)."),
)


#: The commands, in the order ``--help`` lists them.
COMMAND_NAMES = tuple(name for name, *_ in _COMMANDS)


def help_text(command: str | None = None) -> str:
    """The ``--help`` text of ``command`` (of ``mavsysid`` itself when None).

    Parameters
    ----------
    command : str, optional
        A command name from `COMMAND_NAMES`, whose subcommand help is returned; the
        top-level help listing all commands when None.
    """
    parser = build_parser(command)
    if command is None:
        return parser.format_help()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[command].format_help()


def _requested_command(argv: Sequence[str]) -> str | None:
    # Top-level options take no values, so the first bare word names the command.
    return next((arg for arg in argv if not arg.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser of the console script.

    Parameters
    ----------
    command : str, optional
        Only this command's options are added (its module alone is imported); all
        commands' options when None.
    """
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--version", action="version", version=f"mavsysid {__version__}")
    common.add_argument("-v", "--verbose", dest="verbosity", action="count",
                        default=argparse.SUPPRESS, help="print more detail")
    common.add_argument("-q", "--quiet", dest="quiet", action="store_true",
                        default=argparse.SUPPRESS, help="print only the essential result")

    parser = argparse.ArgumentParser(
        prog="mavsysid", parents=[common],
        description="Plan, fly, estimate and diagnose multirotor system-identification flights.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    for name, module_name, summary, description in _COMMANDS:
        subparser = sub.add_parser(name, parents=[common], help=summary,
                                   description=description)
        if command is None or command == name:
            module = importlib.import_module(module_name)
            # A command whose description lists a registry (effects, log formats) says it.
            subparser.description = getattr(module, "DESCRIPTION", description)
            module.add_arguments(subparser)
            subparser.set_defaults(run=module.main)

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mavsysid`` console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_requested_command(argv) or "")
    args = parser.parse_args(argv)
    verbosity = getattr(args, "verbosity", 0)
    args.verbosity = -1 if getattr(args, "quiet", False) else verbosity
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(args.command)
            return args.run(args)
    except MavsysidError as error:
        print(f"mavsysid {args.command}: error: {_one_line(str(error))}", file=sys.stderr)
        return exit_code(error)
    except (KeyboardInterrupt, SystemError) as error:
        if not _caused_by_interrupt(error):
            return _internal_error(args.command, error)
        print(f"mavsysid {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as error:  # the last resort: never a bare traceback
        return _internal_error(args.command, error)


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _internal_error(command: str, error: BaseException) -> int:
    """Report an unexpected exception in one line (the traceback with MAVSYSID_DEBUG=1)."""
    if os.environ.get(DEBUG_ENV, "") not in ("", "0"):
        traceback.print_exception(error, file=sys.stderr)
    print(f"mavsysid {command}: internal error: {type(error).__name__}: "
          f"{_one_line(str(error))} (please report; {DEBUG_ENV}=1 shows the traceback)",
          file=sys.stderr)
    return EXIT_INTERNAL


def _one_line_warning(command: str) -> Callable[..., None]:
    """A `warnings.showwarning` printing mavsysid's own warnings as one line."""
    default = warnings.showwarning

    def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: TextIO | None = None, line: str | None = None) -> None:
        if not category.__module__.startswith("mavsysid"):
            default(message, category, filename, lineno, file, line)
            return
        print(f"mavsysid {command}: warning: {_one_line(str(message))}",
              file=sys.stderr if file is None else file)

    return show


def exit_code(error: MavsysidError) -> int:
    """The console script's exit code for ``error`` (see `EXIT_CODES`)."""
    return next(EXIT_CODES[kind] for kind in type(error).__mro__ if kind in EXIT_CODES)


def _caused_by_interrupt(error: BaseException) -> bool:
    # A Ctrl-C that lands inside a compiled numba kernel surfaces as a SystemError
    # ("returned a result with an exception set") chained onto the KeyboardInterrupt.
    seen: set[int] = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False
