"""``mavsysid restore``: put back the autopilot parameters a flight changed.

A thin layer over `mavsysid.pipeline.stream.restore_flight_parameters`: after a streamer
that could not restore them itself (killed, crashed, link lost), write back every
parameter its ``meta.json`` lists with its original value, read them back, and put back
the fence points the vehicle held before the flight. With ``--land`` an armed vehicle is
landed first, to the disarm. Exit codes: 0 restored (or nothing to restore), 2 bad input,
3 refused or failed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mavsysid.flight.mavlink_setup import signing_key_from_file
from mavsysid.pipeline.stream import restore_flight_parameters

__all__ = ["add_arguments", "main"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid restore``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The ``restore`` subcommand's parser; its options are added to it in place.
    """
    parser.add_argument("flight_dir", type=Path, metavar="FLIGHT_DIR",
                        help="the flight directory whose meta.json lists the parameters")
    parser.add_argument("--connect", default="udp:127.0.0.1:14550", metavar="LINK",
                        help="the vehicle's MAVLink connection, as for `mavsysid stream` "
                        "(default: udp:127.0.0.1:14550)")
    parser.add_argument("--signing-key", type=Path, metavar="FILE",
                        help="MAVLink 2 signing: a file holding the passphrase")
    parser.add_argument("--heartbeat-timeout", type=float, default=30.0, metavar="S",
                        help="how long to wait for the vehicle's heartbeat (default: 30 s)")
    parser.add_argument("--land", action="store_true",
                        help="an armed vehicle is sent to LAND, landed to the disarm (forced "
                        "only when it rests at its take-off height and its land detector "
                        "missed the touchdown), then restored (by default an armed vehicle "
                        "is refused)")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line: the options of `add_arguments` and ``verbosity``
        (-1 quiet, 0 default, more with ``-v``).
    """
    key = None if args.signing_key is None else signing_key_from_file(args.signing_key)

    def say(text: str) -> None:
        if args.verbosity >= 0:
            print(f"mavsysid restore: {text}", file=sys.stderr, flush=True)

    outcome = restore_flight_parameters(args.flight_dir, args.connect, key,
                                        args.heartbeat_timeout, args.land, say=say)
    if args.verbosity >= 0:
        for name, (found, original) in outcome.restored.items():
            print(f"  {name:<16} {found:g} -> {original:g}")
        for name, original in outcome.unchanged.items():
            print(f"  {name:<16} {original:g} (already)")
    if outcome.read_back:
        print(f"restored {len(outcome.restored)} parameter(s), {len(outcome.unchanged)} "
              f"already in place; all {len(outcome.read_back)} read back as before the flight")
    if outcome.fence_points is not None:
        print(f"fence points as before the flight: {outcome.fence_points}"
              + (" (the fence mission cleared)" if outcome.fence_points == 0 else ""))
    return 0
