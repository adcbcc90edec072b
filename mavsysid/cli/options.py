"""Option parsing shared by several commands: the flight log and vehicle, the link to a
vehicle, comma-separated numbers, positive numbers, negative values."""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

from mavsysid.errors import InputError
from mavsysid.planner.settings import PlannerSettings

__all__ = [
    "DEFAULT_BOX",
    "LINK_TIMEOUTS",
    "OUTPUT_OPTION",
    "add_link_arguments",
    "add_log_arguments",
    "add_noise_argument",
    "add_output_folder",
    "add_window_arguments",
    "allow_negative_values",
    "parse_numbers",
    "require_imbalance",
    "require_positive",
]

#: The one name of the output-folder option of every command that writes a folder.
OUTPUT_OPTION = "--log-dir"

#: The planner's default flight box as the ``--box`` text of the commands.
DEFAULT_BOX = ",".join(f"{v:g}" for v in PlannerSettings.box)


def add_log_arguments(parser: argparse.ArgumentParser, kinds: str) -> None:
    """The flight log and the vehicle of the commands that read a log (estimate, diagnose).

    Parameters
    ----------
    parser : argparse.ArgumentParser
    kinds : str
        The logs the command reads, in words (`mavsysid.estimation.describe_log_kinds`).
    """
    parser.add_argument("log", type=Path, help=f"flight log: {kinds}; or a flight "
                        "directory (its log with the most telling rotor speeds)")
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path (default: firefly)")


#: The positive options of `add_link_arguments` (argparse destinations).
LINK_TIMEOUTS = ("speedup", "heartbeat_timeout", "prearm_timeout", "position_timeout",
                 "max_tracking_error")


def add_noise_argument(parser: argparse.ArgumentParser) -> None:
    """``--noise-from``, shared by ``plan`` and ``experiment``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The subcommand's parser; the option is added to it in place.
    """
    parser.add_argument("--noise-from", type=Path, nargs="+", metavar="FLIGHT",
                        help="plan for the noise the estimator met on earlier flights of "
                        "this vehicle: each an estimate.json, or the flight directory "
                        "holding one (pose σ and rate, fitted unmodelled force and moment; "
                        "the median over several; default: the vehicle file's [noise] and "
                        "a 100 Hz pose)")


def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    """The link options of the commands that fly a vehicle (stream, experiment): signing,
    clock speed-up, the waits before flying, the fence, the in-flight guards and the log
    download.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser; the options are added to it in place.
    """
    parser.add_argument("--signing-key", type=Path, metavar="FILE",
                        help="MAVLink 2 signing: a file holding the passphrase")
    parser.add_argument("--speedup", type=float, default=1.0, metavar="K",
                        help="run the clock K times faster (only against `mavsysid sim "
                        "--speedup K`; default: 1)")
    parser.add_argument("--heartbeat-timeout", type=float, default=30.0, metavar="S",
                        help="how long to wait for the vehicle's first heartbeat, wall "
                        "time (default: 30 s)")
    parser.add_argument("--prearm-timeout", type=float, default=60.0, metavar="S",
                        help="how long to wait for the vehicle's pre-arm checks to pass "
                        "(default: 60 s)")
    parser.add_argument("--position-timeout", type=float, default=90.0, metavar="S",
                        help="how long to wait for a usable local position (default: 90 s)")
    parser.add_argument("--no-fence", action="store_true",
                        help="fly without the autopilot's geofence around the box (by default "
                        "a vehicle without a working fence is refused)")
    parser.add_argument("--no-log-download", action="store_true",
                        help="after landing, do not download the vehicle's own log of the "
                        "flight (by default it goes into the flight directory as "
                        "autopilot.bin / autopilot.ulg)")
    parser.add_argument("--max-tracking-error", type=float, default=1.0, metavar="M",
                        help="abort to hold, then land, beyond this distance from the "
                        "setpoint; reported from half of it (default: 1.0 m)")
    parser.add_argument("--max-motor-imbalance", type=float, default=2.0, metavar="R",
                        help="abort to hold, then land, when a motor is asked for R times the "
                        "thrust of its mirror (the rotor opposite) over 2 s: a weak motor or "
                        "propeller; reported from 1.25 (default: 2)")
    parser.add_argument("--lockstep", action="store_true",
                        help="test/bench tool: share one simulated clock with `mavsysid sim "
                        "--lockstep` (same flight idle or overloaded); other vehicles: the "
                        "wall clock")


def require_imbalance(args: argparse.Namespace) -> None:
    """Refuse a ``--max-motor-imbalance`` that is not a finite ratio above 1 (one line).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``max_motor_imbalance``).

    Raises
    ------
    InputError
    """
    value = args.max_motor_imbalance
    if not (value > 1.0 and value < math.inf):
        raise InputError(f"--max-motor-imbalance {value:g}: expected a ratio above 1")


def require_positive(args: argparse.Namespace, options: tuple[str, ...]) -> None:
    """Refuse, in one line naming it, an option of ``options`` that is not a positive
    finite number.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    options : tuple of str
        argparse destinations (``"heartbeat_timeout"`` for ``--heartbeat-timeout``).

    Raises
    ------
    InputError
    """
    for option in options:
        value = getattr(args, option)
        if not (value > 0.0 and value < math.inf):
            raise InputError(f"--{option.replace('_', '-')} {value:g}: expected a positive "
                             "number")


def add_output_folder(parser: argparse.ArgumentParser, default: str, what: str,
                      old_names: tuple[str, ...] = ()) -> None:
    """``--log-dir DIR`` (`OUTPUT_OPTION`, into ``args.log_dir``): where the command
    writes; ``old_names`` stay accepted, hidden from ``--help``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser; the option is added to it in place.
    default : str
        The folder used without the option (``args.log_dir`` is then ``Path(default)``).
    what : str
        The ``--help`` text of the option, e.g. "folder for the new flight directory";
        " (default: DEFAULT)" is appended.
    old_names : tuple of str, optional
        Former spellings of the option (e.g. ``("--logs",)``), still accepted into
        ``args.log_dir`` but not listed in ``--help``.
    """
    parser.add_argument(OUTPUT_OPTION, dest="log_dir", type=Path, default=Path(default),
                        metavar="DIR", help=f"{what} (default: {default})")
    for name in old_names:
        parser.add_argument(name, dest="log_dir", type=Path, default=argparse.SUPPRESS,
                            help=argparse.SUPPRESS)


def add_window_arguments(parser: argparse.ArgumentParser) -> None:
    """``--start``/``--end``: the part of the log to use (estimate, diagnose)."""
    parser.add_argument("--start", type=float, metavar="S",
                        help="use the log from this time on, s on the log's clock (default: "
                        "the trajectory flown by mavsysid stream, else the longest "
                        "GUIDED/OFFBOARD span, else the whole log)")
    parser.add_argument("--end", type=float, metavar="S",
                        help="use the log up to this time, s on the log's clock")


def allow_negative_values(parser: argparse.ArgumentParser) -> None:
    """Let values such as ``--box -2,-2,0.5,2,2,2.5`` through as option values.

    Python < 3.13 takes any argument that starts with "-" and is not a plain number for an
    option (3.13 uses this very pattern).
    """
    parser._negative_number_matcher = re.compile(r"-\.?\d")  # type: ignore[attr-defined]


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
