"""``mavsysid simulate``: fly in the offline simulator.

A thin layer over `mavsysid.pipeline.simulate.run_offline_flight`, which tests
call directly. It flies the built-in excitation, or a trajectory file (``--trajectory``,
e.g. from ``mavsysid plan``), with the vehicle config's known effects and any hidden ones
(``--hidden-effect NAME:KEY=VALUE,...``, repeatable), e.g.::

    mavsysid simulate --hidden-effect motor_lag:tau=0.04 --hidden-effect wind:x=2
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mavsysid.cli.options import add_output_folder
from mavsysid.flight.offline.simulator import SimulationSettings
from mavsysid.pipeline.simulate import (
    OfflineFlight,
    parse_hidden_effects,
    run_offline_flight,
)
from mavsysid.vehicle.model_effects import EFFECTS

__all__ = ["add_arguments", "format_summary", "main"]


def format_summary(flight: OfflineFlight, verbosity: int = 0) -> str:
    """The text printed after a flight (``verbosity`` < 0: only the flight directory)."""
    if verbosity < 0:
        return str(flight.directory)
    r, s, d = flight.result, flight.settings, flight.directory
    lines = [
        f"Simulated {flight.config.name} flying {flight.trajectory_name} "
        f"({r.times[-1]:.1f} s).",
        f"  pose log   {d / 'pose.csv'}  ({r.times.size} samples at {s.log_rate:g} Hz)",
        f"  truth      {d / 'truth.csv'}",
        f"  metadata   {d / 'meta.json'}",
        f"  tracking   position RMS {1000 * r.position_rms:.1f} mm, rotor saturation "
        f"{100 * r.saturated_fraction:.1f} % of control ticks",
        f"  speed      {r.realtime_factor:.0f}x real time ({s.physics_rate:g} Hz physics)",
    ]
    for label, effects in (("effects", flight.model_effects),
                           ("hidden", flight.hidden_effects)):
        if effects:
            lines.append(f"  {label:<10} " + "; ".join(map(repr, effects)))
    if verbosity > 0:
        lines.append(f"  seed       {s.seed}; control {s.control_rate:g} Hz; "
                     f"motor lag {'on' if s.motor_lag else 'off'}; "
                     f"sensor noise {'on' if s.sensor_noise else 'off'}")
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the offline-flight commands."""
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path (default: firefly)")
    add_output_folder(parser, "logs", "folder for the new flight directory", ("--logs",))
    parser.add_argument("--name", help="flight directory name (default: a timestamp)")
    parser.add_argument("--duration", type=float,
                        help="built-in excitation duration in s (default: 30)")
    parser.add_argument("--trajectory", type=Path, metavar="FILE",
                        help="fly this trajectory file (from mavsysid plan) instead of the "
                        "built-in excitation")
    parser.add_argument("--hidden-effect", action="append", default=[], metavar="SPEC",
                        help="add a model effect to the truth only, as NAME:KEY=VALUE,... "
                        "(repeatable), e.g. motor_lag:tau=0.04 or wind:x=2; names: "
                        f"{', '.join(EFFECTS)}")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default: 0)")
    parser.add_argument("--physics-rate", type=float, default=1000.0, metavar="HZ",
                        help="truth integration rate, >= 500 Hz (default: 1000)")
    parser.add_argument("--control-rate", type=float, default=500.0, metavar="HZ",
                        help="controller rate (default: 500)")
    parser.add_argument("--log-rate", type=float, default=100.0, metavar="HZ",
                        help="pose log rate (default: 100)")
    parser.add_argument("--no-noise", action="store_true",
                        help="log the true pose, rotor speeds and IMU without sensor noise "
                        "(nor IMU bias)")
    parser.add_argument("--no-motor-lag", action="store_true",
                        help="rotors reach commanded speeds instantly")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    settings = SimulationSettings(
        physics_rate=args.physics_rate, control_rate=args.control_rate, log_rate=args.log_rate,
        motor_lag=not args.no_motor_lag, sensor_noise=not args.no_noise, seed=args.seed,
    )
    hidden = parse_hidden_effects(args.hidden_effect)
    flight = run_offline_flight(args.vehicle, args.log_dir, args.name, args.duration, settings,
                                hidden, args.trajectory)
    print(format_summary(flight, args.verbosity))
    return 0
