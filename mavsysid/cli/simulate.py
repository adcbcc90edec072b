"""``mavsysid simulate``: fly in the offline simulator.

The command is a thin layer over `run_offline_flight`, which tests call directly. It
flies the built-in excitation, or a trajectory file (``--trajectory``, e.g. from
``mavsysid plan``), with the vehicle config's known effects and any hidden ones
(``--hidden-effect NAME:KEY=VALUE,...``, repeatable), e.g.::

    mavsysid simulate --hidden-effect motor_lag:tau=0.04 --hidden-effect wind:x=2
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mavsysid.errors import InputError, JobFailedError
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationResult, SimulationSettings, Simulator
from mavsysid.formats.flight_dir import new_flight_dir
from mavsysid.formats.trajectory_file import read_trajectory
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.model_effects import ModelEffect, parse_effect
from mavsysid.vehicle.trajectory import Trajectory

__all__ = [
    "OfflineFlight",
    "add_arguments",
    "format_summary",
    "main",
    "parse_hidden_effects",
    "run_offline_flight",
]

#: Duration of the built-in excitation unless --duration says otherwise, s.
DEFAULT_DURATION = 30.0

#: A simulated vehicle this far from its reference has lost the trajectory, m.
LOST_TRACK_DISTANCE = 0.5


@dataclass(frozen=True)
class OfflineFlight:
    """A finished simulated flight: the vehicle, where it was logged, and the result."""

    config: VehicleConfig
    directory: Path
    result: SimulationResult
    settings: SimulationSettings
    hidden_effects: tuple[ModelEffect, ...] = ()
    trajectory_name: str = "the built-in excitation trajectory"
    model_effects: tuple[ModelEffect, ...] = field(default=())


def parse_hidden_effects(texts: Sequence[str], option: str = "--hidden-effect"
                         ) -> tuple[ModelEffect, ...]:
    """Catalogue effects from ``NAME:KEY=VALUE,...`` strings; a bad one is an `InputError`.

    The one-line message names the option, the text and the problem (an unknown effect
    with the list of names, an unknown parameter with the known ones, a non-number).
    """
    effects = []
    for text in texts:
        try:
            effects.append(parse_effect(text))
        except InputError as error:
            raise InputError(f"{option} {text!r}: {error}") from None
    return tuple(effects)


def run_offline_flight(
    vehicle: str | Path = "firefly",
    logs: str | Path = "logs",
    name: str | None = None,
    duration: float | None = None,
    settings: SimulationSettings | None = None,
    hidden_effects: Sequence[ModelEffect] = (),
    trajectory: str | Path | None = None,
) -> OfflineFlight:
    """Simulate a vehicle flying the built-in excitation (or a trajectory file) and log it.

    Parameters
    ----------
    vehicle : str or Path
        Shipped vehicle name or TOML path; its ``[effects]`` are simulated as known.
    logs : str or Path
        Folder that receives the new flight directory.
    name : str, optional
        Flight directory name; a timestamp by default.
    duration : float, optional
        Built-in excitation duration, s (at least 10 s: two 3 s ramps and a figure;
        30 s by default). Not with ``trajectory``, which has its own.
    settings : SimulationSettings, optional
    hidden_effects : sequence of ModelEffect
        Truth the model does not know (recorded in meta.json ``truth.effects``).
    trajectory : str or Path, optional
        A trajectory file (`mavsysid.formats.trajectory_file`) to fly instead of the excitation.
    """
    config = load_vehicle(vehicle)
    settings = settings or SimulationSettings()
    settings.steps()  # reject bad rates before creating a directory
    if trajectory is not None:
        if duration is not None:
            raise InputError("--duration: only for the built-in excitation; a trajectory "
                             "file has its own duration")
        document = read_trajectory(trajectory)
        flown: Trajectory = document.trajectory
        what = f"the trajectory {trajectory} ({document.kind})"
        description = {"kind": document.kind, "file": str(trajectory)}
    else:
        duration = DEFAULT_DURATION if duration is None else duration
        if not duration >= 10.0:
            raise InputError(f"--duration {duration:g}: expected at least 10 s")
        flown = excitation_trajectory(ExcitationSpec(duration=duration))
        what = "the built-in excitation trajectory"
        description = {"kind": "builtin-excitation"}
    _check_rotor_speeds(flown, config, what)
    directory = new_flight_dir(logs, name)
    effects = [hidden_effect(e) for e in hidden_effects]
    result = Simulator(config, settings=settings, effects=effects).run(
        flown, directory, description=description
    )
    error = np.linalg.norm(result.states[:, 0:3] - result.reference_position, axis=1).max()
    if error > LOST_TRACK_DISTANCE:
        raise JobFailedError(
            f"the simulated {config.name} lost the trajectory (up to {error:.2f} m off, rotors "
            f"saturated in {100 * result.saturated_fraction:.0f} % of control ticks); "
            f"the log is kept in {directory}"
        )
    return OfflineFlight(config, directory, result, settings, tuple(hidden_effects), what,
                         config.effects)


def _check_rotor_speeds(trajectory: Trajectory, config: VehicleConfig, what: str) -> None:
    """Refuse a trajectory whose flatness rotor speeds leave the vehicle's limits."""
    t = np.linspace(0.0, trajectory.duration, int(trajectory.duration * 100) + 1)
    low, high = np.inf, -np.inf
    for chunk in np.array_split(t, max(1, t.size // 10_000)):
        n2 = flat_to_state(trajectory.flat_outputs(chunk), config).rotor_speeds_squared
        low, high = min(low, float(n2.min())), max(high, float(n2.max()))
    lim = config.limits
    if low < lim.rotor_speed_min**2 or high > lim.rotor_speed_max**2:
        raise JobFailedError(
            f"{config.source}: {what} needs rotor speeds from "
            f"{np.sqrt(max(low, 0.0)):.0f} to {np.sqrt(high):.0f} rad/s, outside [limits] "
            f"[{lim.rotor_speed_min:g}, {lim.rotor_speed_max:g}] rad/s of this vehicle"
        )


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
    parser.add_argument("--logs", default="logs", type=Path,
                        help="folder for the new flight directory (default: logs)")
    parser.add_argument("--name", help="flight directory name (default: a timestamp)")
    parser.add_argument("--duration", type=float,
                        help="built-in excitation duration in s (default: 30)")
    parser.add_argument("--trajectory", type=Path, metavar="FILE",
                        help="fly this trajectory file (from mavsysid plan) instead of the "
                        "built-in excitation")
    parser.add_argument("--hidden-effect", action="append", default=[], metavar="SPEC",
                        help="add a model effect to the truth only, as NAME:KEY=VALUE,... "
                        "(repeatable), e.g. motor_lag:tau=0.04 or wind:x=2; names: "
                        "body_drag, rotor_drag_linear, motor_lag, pose_delay, marker_offset, "
                        "cog_offset, wind, thrust_drift, ground_effect")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default: 0)")
    parser.add_argument("--physics-rate", type=float, default=1000.0, metavar="HZ",
                        help="truth integration rate, >= 500 Hz (default: 1000)")
    parser.add_argument("--control-rate", type=float, default=500.0, metavar="HZ",
                        help="controller rate (default: 500)")
    parser.add_argument("--log-rate", type=float, default=100.0, metavar="HZ",
                        help="pose log rate (default: 100)")
    parser.add_argument("--no-noise", action="store_true",
                        help="log the true pose and rotor speeds without sensor noise")
    parser.add_argument("--no-motor-lag", action="store_true",
                        help="rotors reach commanded speeds instantly")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    settings = SimulationSettings(
        physics_rate=args.physics_rate, control_rate=args.control_rate, log_rate=args.log_rate,
        motor_lag=not args.no_motor_lag, sensor_noise=not args.no_noise, seed=args.seed,
    )
    hidden = parse_hidden_effects(args.hidden_effect)
    flight = run_offline_flight(args.vehicle, args.logs, args.name, args.duration, settings,
                                hidden, args.trajectory)
    print(format_summary(flight, args.verbosity))
    return 0
