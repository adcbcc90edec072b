"""One offline flight: the built-in excitation or a trajectory file, flown by the offline
simulator with the vehicle's known effects and any hidden ones, logged to a new flight
directory.

`run_offline_flight` is what ``mavsysid simulate`` and the experiments call; tests call it
directly. `parse_hidden_effects` reads the ``--hidden-effect NAME:KEY=VALUE,...`` texts of
the commands that fly a simulated vehicle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationResult, SimulationSettings, Simulator
from mavsysid.formats.flight_dir import new_flight_dir
from mavsysid.formats.trajectory_file import read_trajectory
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.model_effects import ModelEffect, parse_effect
from mavsysid.vehicle.trajectory import Trajectory

from mavsysid.errors import InputError, JobFailedError

__all__ = [
    "DEFAULT_DURATION",
    "LOST_TRACK_DISTANCE",
    "OfflineFlight",
    "check_rotor_speeds",
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
    check_rotor_speeds(flown, config, what)
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


def check_rotor_speeds(trajectory: Trajectory, config: VehicleConfig, what: str) -> None:
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
