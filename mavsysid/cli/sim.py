"""``mavsysid sim``: a simulated MAVLink vehicle endpoint (ArduPilot Copter or PX4).

A thin layer over `mavsysid.flight.simvehicle.endpoint.SimEndpoint` (which tests also run in a
thread):
check the options, run until Ctrl-C, SIGTERM or ``--duration`` sim seconds, close the
truth log cleanly, print a one-line summary and exit 0.
"""

from __future__ import annotations

import argparse
import math
import re
import signal
import sys
from pathlib import Path

from mavsysid.cli.options import allow_negative_values, parse_numbers
from mavsysid.errors import InputError
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.mavlink_setup import signing_key_from_file
from mavsysid.flight.simvehicle.endpoint import SimEndpoint, SimSettings
from mavsysid.pipeline.simulate import parse_hidden_effects
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import EFFECTS

__all__ = ["add_arguments", "main", "settings_from_args"]

_MAX_SPEEDUP = 100.0
_FAULT_RE = re.compile(r"^(deny-arm|no-land-detect|mode:([A-Z_]+)@(\d+(?:\.\d*)?)|"
                       r"silent@(\d+(?:\.\d*)?)|"
                       r"weak-motor:(\d+)=(\d*\.?\d+)(?:@(\d+(?:\.\d*)?))?)$")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid sim``."""
    allow_negative_values(parser)  # "--start -1,2,0"
    parser.add_argument("--connect", default="udpout:127.0.0.1:14550", metavar="URL",
                        help="udpout:HOST:PORT (send to a ground station), tcpin:HOST:PORT "
                        "or udpin:HOST:PORT (listen), or a serial device[:BAUD] such as "
                        "/dev/ttyUSB0:57600 (default: udpout:127.0.0.1:14550)")
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path (default: firefly)")
    parser.add_argument("--autopilot", choices=("ardupilot", "px4"), default="ardupilot",
                        help="which autopilot to behave like (default: ardupilot)")
    parser.add_argument("--speedup", type=float, default=1.0, metavar="K",
                        help="run sim time K times faster than wall time (default: 1)")
    parser.add_argument("--ekf-delay", type=float, default=2.0, metavar="S",
                        help="sim seconds before a position estimate exists (default: 2)")
    parser.add_argument("--start", default="0,0,0", metavar="X,Y,Z",
                        help="start position on the ground, m, world ENU (default: 0,0,0)")
    parser.add_argument("--signing-key", type=Path, metavar="FILE",
                        help="MAVLink 2 signing: a file holding the passphrase (key = "
                        "sha256 of it); unsigned commands and setpoints are then ignored")
    parser.add_argument("--truth-log", type=Path, metavar="DIR",
                        help="write truth.csv, pose.csv and meta.json (true θ) into DIR")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop after S sim seconds (default: run until interrupted)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default: 0)")
    parser.add_argument("--lockstep", action="store_true",
                        help="test/bench tool: lock-step with `mavsysid stream --lockstep` "
                        "(--speedup is then the fastest pace); others: the wall clock")
    parser.add_argument("--theta-scale", metavar="F[,F,F,F,F,F]",
                        help="true θ = nominal θ × F (one factor, or six for c_T,c_D,c_M,"
                        "j_x,j_y,j_z); the controller keeps the nominal θ (default: 1)")
    parser.add_argument("--no-noise", action="store_true",
                        help="publish the true pose, rotor speeds and IMU (no noise, no IMU "
                        "bias)")
    parser.add_argument("--hidden-effect", action="append", default=[], metavar="SPEC",
                        help="add a model effect to the truth only, as NAME:KEY=VALUE,... "
                        "(repeatable), e.g. motor_lag:tau=0.04 or wind:x=2; names: "
                        f"{', '.join(EFFECTS)}")
    parser.add_argument("--fault", action="append", default=[], metavar="FAULT",
                        help="inject a fault (repeatable): deny-arm; no-land-detect (a touchdown "
                        "in LAND goes undetected: armed on the ground, a disarm refused unless "
                        "forced, as ArduCopter in strong wind); mode:NAME@S (a pilot "
                        "switches to mode NAME at sim time S); silent@S (the link goes quiet); "
                        "weak-motor:N=F[@S] (motor output N makes F of its thrust, 0 < F <= 1, "
                        "from sim time S, default 0; as SITL's SIM_ENGINE_MUL)")


def _weak_motor(text: str, match: re.Match[str], rotors: int) -> tuple[int, float, float]:
    motor, factor = int(match.group(5)), float(match.group(6))
    if not 1 <= motor <= rotors:
        raise InputError(f"--fault {text!r}: motor {motor}; the vehicle has motors 1 to "
                         f"{rotors}")
    if not 0.0 < factor <= 1.0:
        raise InputError(f"--fault {text!r}: thrust factor {factor:g}; expected 0 < F <= 1")
    return motor, factor, float(match.group(7) or 0.0)


def _fault_settings(faults: list[str], autopilot: Autopilot, rotors: int) -> dict:
    out: dict = {}
    for text in faults:
        match = _FAULT_RE.match(text)
        if match is None:
            raise InputError(f"--fault {text!r}: expected deny-arm, no-land-detect, mode:NAME@S, "
                             "silent@S or weak-motor:N=F[@S]")
        if match.group(1) == "deny-arm":
            out["deny_arm"] = True
        elif match.group(1) == "no-land-detect":
            out["land_detector_fails"] = True
        elif match.group(2):
            names = [*autopilot.modes, *(["RTL"] if autopilot is Autopilot.PX4 else [])]
            if match.group(2) not in names:
                raise InputError(f"--fault {text!r}: unknown {autopilot.name.lower()} mode "
                                 f"{match.group(2)}; expected one of {', '.join(names)}")
            out["pilot_mode"] = (match.group(2), float(match.group(3)))
        elif match.group(4):
            out["silent_after"] = float(match.group(4))
        else:
            out["weak_motor"] = _weak_motor(text, match, rotors)
    return out


def settings_from_args(args: argparse.Namespace) -> SimSettings:
    """`SimSettings` from the command line; bad values are one-line `InputError`s."""
    autopilot = Autopilot.ARDUPILOT if args.autopilot == "ardupilot" else Autopilot.PX4
    if not (math.isfinite(args.speedup) and 0.0 < args.speedup <= _MAX_SPEEDUP):
        raise InputError(f"--speedup {args.speedup:g}: expected a factor in (0, "
                         f"{_MAX_SPEEDUP:g}]")
    if not (math.isfinite(args.ekf_delay) and args.ekf_delay >= 0.0):
        raise InputError(f"--ekf-delay {args.ekf_delay:g}: expected seconds ≥ 0")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError(f"--duration {args.duration:g}: expected seconds > 0")
    start = parse_numbers(args.start, 3, "--start", "x,y,z")
    scale: tuple[float, ...] = (1.0,) * 6
    if args.theta_scale is not None:
        count = 1 if "," not in args.theta_scale else 6
        scale = parse_numbers(args.theta_scale, count, "--theta-scale", "(c_T,c_D,c_M,j_x,j_y,j_z)")
        scale = scale * 6 if count == 1 else scale
        if not all(f > 0.0 for f in scale):
            raise InputError(f"--theta-scale {args.theta_scale}: factors must be > 0")
    if args.truth_log is not None and (args.truth_log / "pose.csv").exists():
        raise InputError(f"--truth-log {args.truth_log}: already holds a pose log; "
                         "choose a new directory")
    hidden = parse_hidden_effects(args.hidden_effect)
    key = None if args.signing_key is None else signing_key_from_file(args.signing_key)
    rotors = load_vehicle(args.vehicle).rotor_count
    return SimSettings(autopilot=autopilot, speedup=args.speedup, ekf_delay=args.ekf_delay,
                       start=start, seed=args.seed, theta_scale=scale,  # type: ignore[arg-type]
                       sensor_noise=not args.no_noise, duration=args.duration, signing_key=key,
                       truth_log=args.truth_log, hidden_effects=hidden, lockstep=args.lockstep,
                       **_fault_settings(args.fault, autopilot, rotors))


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code (0 also after Ctrl-C or SIGTERM)."""
    settings = settings_from_args(args)
    config = load_vehicle(args.vehicle)
    endpoint = SimEndpoint(args.connect, config, settings)

    def stop(signum: int, frame: object) -> None:
        endpoint.stop()

    previous = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        if args.verbosity >= 0:
            print(f"mavsysid sim: {config.name} as {settings.autopilot.name.lower()} on "
                  f"{args.connect}, speedup {settings.speedup:g}, position after "
                  f"{settings.ekf_delay:g} s; Ctrl-C to stop", flush=True)
        summary = endpoint.run()
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    print(f"mavsysid sim: {summary.line()}", file=sys.stdout, flush=True)
    return 0
