"""Hidden-truth flights for the diagnosis tests and bench.

`hidden_flight` flies a trajectory in the simulator with catalogue effects
(`vehicle.model_effects`) made true and returns the pose log as `FlightData`. A small
adapter turns a `ModelEffect` into the simulator's `TruthEffect`: wrench effects through
the wrench hook, pose effects through the measurement hook (with a pose history for
the delay), motor lag by setting the truth's motor time constant and logging the
commanded speeds (DESIGN.md: a hidden motor lag logs commands).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from estimation.flight_data import FlightData
from flight.effects import TruthEffect
from flight.excitation import ExcitationSpec, excitation_trajectory
from flight.simulator import SimulationSettings, Simulator
from vehicle.config import VehicleConfig
from vehicle.flight_dir import read_meta
from vehicle.model_effects import EffectInputs, ModelEffect
from vehicle.poselog import read_pose_log
from vehicle.trajectory import PiecewisePolynomial, Trajectory

__all__ = ["CatalogueTruth", "ground_trajectory", "hidden_flight"]


class CatalogueTruth(TruthEffect):
    """A catalogue effect on the simulator's truth side."""

    def __init__(self, effect: ModelEffect, config: VehicleConfig, theta: np.ndarray) -> None:
        self.effect = effect
        self.name = effect.name
        self._r = config.rotor_positions
        self._theta = np.asarray(theta, float)
        self._hist_t: list[float] = []
        self._hist_p: list[np.ndarray] = []
        self._hist_q: list[np.ndarray] = []

    def parameters(self) -> dict[str, float | list[float]]:
        return self.effect.as_dict()

    def reset(self, physics_dt: float) -> None:
        self._hist_t, self._hist_p, self._hist_q = [], [], []

    def wrench(self, t: float, x: np.ndarray, n: np.ndarray):  # noqa: ANN201
        if "wrench" not in self.effect.channels:
            return None
        inputs = EffectInputs(np.array([t]), x[None, 0:3], x[None, 6:10], x[None, 3:6],
                              x[None, 10:13], n[None, :], self._theta, self._r)
        f, m = self.effect.wrench(inputs)
        return f[0], m[0]

    def measure_pose(self, t: float, position: np.ndarray, quaternion: np.ndarray):  # noqa: ANN201
        if "pose" not in self.effect.channels:
            return position, quaternion
        self._hist_t.append(t)
        self._hist_p.append(position.copy())
        self._hist_q.append(quaternion.copy())
        k = min(len(self._hist_t), 50)
        tt = np.array(self._hist_t[-k:])
        p, q = self.effect.measured_pose(tt, np.array(self._hist_p[-k:]),
                                         np.array(self._hist_q[-k:]))
        return p[-1], q[-1]

    def logged_rotor_speeds(self, t: float, actual: np.ndarray, commanded: np.ndarray):  # noqa: ANN201
        return commanded if "rotor_speeds" in self.effect.channels else actual


def ground_trajectory(duration: float = 30.0, low: float = 0.17) -> PiecewisePolynomial:
    """The excitation figure with two descents to ``low`` m (CoG height) above the ground.

    Hover-to-hover Hermite segments: 1.5 m → low (held 2 s) → 1.5 m, once in the first
    70 % of the flight and once in the last 30 %, so held-out data contains ground-near
    flight. Rotor hubs sit 0.037 m above the CoG, so ``low`` = 0.17 puts them within one
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
    trajectory: Trajectory | None = None,
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
    """
    theta = config.theta if true_theta is None else np.asarray(true_theta, float)
    sim_config = config
    for effect in effects:
        if "rotor_speeds" in effect.channels:
            sim_config = replace(config, motor=replace(config.motor,
                                                       time_constant=float(effect.values[0])))
    truths = [CatalogueTruth(e, config, theta) for e in effects]
    trajectory = trajectory or excitation_trajectory(ExcitationSpec(duration=duration))
    Simulator(sim_config, true_theta=theta, settings=SimulationSettings(seed=seed),
              effects=truths).run(trajectory, directory)
    log = read_pose_log(directory / "pose.csv", config.rotor_count)
    truth = read_meta(directory / "meta.json")["truth"]
    return FlightData(log.t, log.position, log.quaternion, log.rotor_speeds,
                      str(directory / "pose.csv"), truth=truth)
