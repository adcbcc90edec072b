"""Hidden-truth flights for the diagnosis tests and bench.

`hidden_flight` flies a trajectory in the simulator with catalogue effects
(`mavsysid.vehicle.model_effects`) made true through
`mavsysid.flight.offline.effects.hidden_effect` and returns
the pose log as `FlightData`; `ground_trajectory` is an excitation that also descends
within one rotor diameter of the ground.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from mavsysid.estimation.flight import FlightData
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.model_effects import ModelEffect
from mavsysid.vehicle.trajectory import PiecewisePolynomial, Trajectory

__all__ = ["HIDDEN_MAGNITUDES", "ground_trajectory", "hidden_flight"]

#: Every catalogue effect at the magnitude the tests and benches hide for the Firefly:
#: motor τ 40 ms, pose delay 20 ms, body drag 5 % of the weight at 3 m/s, rotor drag
#: linear in n, wind 2 m/s, marker offset 3 cm, CoG offset 1 cm, thrust −8 % over 30 s,
#: ground effect (ρ = 0.1 m) near the ground, rotor inertia of RotorS's Firefly rotor
#: (5 g at 0.1 m: 1.7·10⁻⁵ kg·m²), rotor speeds sensed through a 20 ms lag.
HIDDEN_MAGNITUDES: dict[str, dict[str, float]] = {
    "motor_lag": {"tau": 0.04},
    "pose_delay": {"delay": 0.02},
    "body_drag": {"k": 0.05 * 1.56779 * 9.81 / 9.0},
    "rotor_drag_linear": {"k": 3e-4},
    "marker_offset": {"x": 0.02, "y": -0.02, "z": 0.01},
    "cog_offset": {"x": 0.006, "y": -0.005, "z": 0.006},
    "wind": {"x": 1.6, "y": 1.2},
    "thrust_drift": {"rate": -0.08 / 30.0},
    "ground_effect": {"rotor_radius": 0.1},
    "rotor_inertia": {"J_r": 1.7e-5},
    "rotor_speed_lag": {"tau": 0.02},
}


def ground_trajectory(duration: float = 30.0, low: float = 0.15) -> PiecewisePolynomial:
    """The excitation figure with two descents to ``low`` m (CoG height) above the ground.

    Hover-to-hover Hermite segments: 1.5 m → low (held 2 s) → 1.5 m, once in the first
    70 % of the flight and once in the last 30 %, so held-out data contains ground-near
    flight. Rotor hubs sit 0.037 m above the CoG, so ``low`` = 0.15 puts them within one
    rotor diameter (0.2 m) of the ground.
    """
    spec = ExcitationSpec(duration=duration)
    base = excitation_trajectory(spec)
    knots = [0.0, 3.0, 6.0, 9.0, 11.0, 14.0, 17.0, 20.0, 23.0, 25.0, 27.0, duration]
    heights = [1.5, 1.5, 0.9, low, low, 1.2, 1.5, 1.0, low, low, 0.8, 1.5]
    times = np.array(knots)
    flat = base.flat_outputs(times)
    pos = np.zeros((times.size, 5, 3))
    # Lateral motion from the excitation figure (scaled down near the ground).
    pos[:, 0, :2] = flat.position[:, :2] * 0.5
    pos[:, 1, :2] = flat.velocity[:, :2] * 0.5
    pos[:, 2, :2] = flat.acceleration[:, :2] * 0.5
    pos[:, 0, 2] = heights
    pos[0, :, :2] = 0.0
    pos[0, 0, :2] = base.flat_outputs(np.array([0.0])).position[0, :2]
    pos[-1, 1:, :] = 0.0
    pos[-1, 0, :2] = base.flat_outputs(np.array([duration])).position[0, :2]
    yaw = np.zeros((times.size, 3))
    yaw[:, 0] = 0.3 * np.sin(0.5 * times)
    yaw[1:-1, 1] = 0.15 * np.cos(0.5 * times[1:-1])
    return PiecewisePolynomial.from_waypoints(times, pos, yaw)


def hidden_flight(
    config: VehicleConfig, directory: Path, effects: Sequence[ModelEffect] = (), seed: int = 0,
    duration: float = 30.0, true_theta: np.ndarray | None = None,
    trajectory: Trajectory | None = None, log_rate: float = SimulationSettings.log_rate,
) -> FlightData:
    """Fly with ``effects`` hidden on the truth side; read the pose log back.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle; its θ is the truth unless ``true_theta`` is given.
    directory : Path
        New flight directory.
    effects : sequence of ModelEffect
        Catalogue effects made true.
    seed : int
        Noise seed.
    duration : float
        s, of the built-in excitation (when no ``trajectory``).
    true_theta : ndarray, shape (6,), optional
    trajectory : Trajectory, optional
    log_rate : float
        Hz, of ``pose.csv``.
    """
    theta = config.theta if true_theta is None else np.asarray(true_theta, float)
    trajectory = trajectory or excitation_trajectory(ExcitationSpec(duration=duration))
    Simulator(config, true_theta=theta, settings=SimulationSettings(seed=seed, log_rate=log_rate),
              effects=[hidden_effect(e) for e in effects]).run(trajectory, directory)
    log = read_pose_log(directory / "pose.csv", config.rotor_count)
    truth = read_meta(directory / "meta.json")["truth"]
    return FlightData(log.t, log.position, log.quaternion, log.rotor_speeds,
                      str(directory / "pose.csv"), truth=truth)
