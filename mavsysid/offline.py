"""``mavsysid simulate``: fly in the offline simulator.

The command is a thin layer over `run_offline_flight`, which tests call directly.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flight.excitation import ExcitationSpec, excitation_trajectory
from flight.simulator import SimulationResult, SimulationSettings, Simulator
from vehicle.config import VehicleConfig, load_vehicle
from vehicle.errors import InputError, JobFailedError
from vehicle.flatness import flat_to_state
from vehicle.flight_dir import new_flight_dir
from vehicle.trajectory import Trajectory

__all__ = ["OfflineFlight", "add_arguments", "format_summary", "main", "run_offline_flight"]

#: A simulated vehicle this far from its reference has lost the trajectory, m.
LOST_TRACK_DISTANCE = 0.5


@dataclass(frozen=True)
class OfflineFlight:
    """A finished simulated flight: the vehicle, where it was logged, and the result."""

    config: VehicleConfig
    directory: Path
    result: SimulationResult
    settings: SimulationSettings


def run_offline_flight(
    vehicle: str | Path = "firefly",
    logs: str | Path = "logs",
    name: str | None = None,
    duration: float = 30.0,
    settings: SimulationSettings | None = None,
) -> OfflineFlight:
    """Simulate a vehicle flying the built-in excitation trajectory and log it.

    Parameters
    ----------
    vehicle : str or Path
        Shipped vehicle name or TOML path.
    logs : str or Path
        Folder that receives the new flight directory.
    name : str, optional
        Flight directory name; a timestamp by default.
    duration : float
        Trajectory duration, s (at least 10 s: two 3 s ramps and a figure).
    settings : SimulationSettings, optional
    """
    config = load_vehicle(vehicle)
    if not duration >= 10.0:
        raise InputError(f"--duration {duration:g}: expected at least 10 s")
    settings = settings or SimulationSettings()
    settings.steps()  # reject bad rates before creating a directory
    trajectory = excitation_trajectory(ExcitationSpec(duration=duration))
    _check_rotor_speeds(trajectory, config)
    directory = new_flight_dir(logs, name)
    result = Simulator(config, settings=settings).run(
        trajectory, directory, description={"kind": "builtin-excitation"}
    )
    error = np.linalg.norm(result.states[:, 0:3] - result.reference_position, axis=1).max()
    if error > LOST_TRACK_DISTANCE:
        raise JobFailedError(
            f"the simulated {config.name} lost the trajectory (up to {error:.2f} m off, rotors "
            f"saturated in {100 * result.saturated_fraction:.0f} % of control ticks); "
            f"the log is kept in {directory}"
        )
    return OfflineFlight(config, directory, result, settings)


def _check_rotor_speeds(trajectory: Trajectory, config: VehicleConfig) -> None:
    """Refuse a trajectory whose flatness rotor speeds leave the vehicle's limits."""
    t = np.linspace(0.0, trajectory.duration, int(trajectory.duration * 100) + 1)
    low, high = np.inf, -np.inf
    for chunk in np.array_split(t, max(1, t.size // 10_000)):
        n2 = flat_to_state(trajectory.flat_outputs(chunk), config).rotor_speeds_squared
        low, high = min(low, float(n2.min())), max(high, float(n2.max()))
    lim = config.limits
    if low < lim.rotor_speed_min**2 or high > lim.rotor_speed_max**2:
        raise JobFailedError(
            f"{config.source}: the built-in excitation needs rotor speeds from "
            f"{np.sqrt(max(low, 0.0)):.0f} to {np.sqrt(high):.0f} rad/s, outside [limits] "
            f"[{lim.rotor_speed_min:g}, {lim.rotor_speed_max:g}] rad/s of this vehicle"
        )


def format_summary(flight: OfflineFlight, verbosity: int = 0) -> str:
    """The text printed after a flight (``verbosity`` < 0: only the flight directory)."""
    if verbosity < 0:
        return str(flight.directory)
    r, s, d = flight.result, flight.settings, flight.directory
    lines = [
        f"Simulated {flight.config.name} flying the built-in excitation trajectory "
        f"({r.times[-1]:.1f} s).",
        f"  pose log   {d / 'pose.csv'}  ({r.times.size} samples at {s.log_rate:g} Hz)",
        f"  truth      {d / 'truth.csv'}",
        f"  metadata   {d / 'meta.json'}",
        f"  tracking   position RMS {1000 * r.position_rms:.1f} mm, rotor saturation "
        f"{100 * r.saturated_fraction:.1f} % of control ticks",
        f"  speed      {r.realtime_factor:.0f}x real time ({s.physics_rate:g} Hz physics)",
    ]
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
    parser.add_argument("--duration", type=float, default=30.0,
                        help="trajectory duration in s (default: 30)")
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
    flight = run_offline_flight(args.vehicle, args.logs, args.name, args.duration, settings)
    print(format_summary(flight, args.verbosity))
    return 0
