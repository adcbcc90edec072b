"""Test helper: a catalogue effect hidden in the simulator's truth (until flight.effects has one)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from flight.effects import TruthEffect
from vehicle.config import VehicleConfig
from vehicle.model_effects import EffectInputs, ModelEffect, MotorLag, PoseDelay


class HiddenEffect(TruthEffect):
    """The catalogue's physics of ``effect`` on the truth side, unknown to the model."""

    def __init__(self, effect: ModelEffect, config: VehicleConfig, theta: np.ndarray) -> None:
        self.effect = effect
        self.name = effect.name
        self._theta = np.asarray(theta, float)
        self._rotors = np.asarray(config.rotor_positions, float)
        self._history: list[tuple[float, np.ndarray, np.ndarray]] = []

    def parameters(self) -> dict[str, float | list[float]]:
        return dict(self.effect.as_dict())

    def reset(self, physics_dt: float) -> None:
        self._history = []

    def logged_rotor_speeds(self, t, actual, commanded):
        return np.array(commanded, float) if isinstance(self.effect, MotorLag) else actual

    def measure_pose(self, t, position, quaternion):
        if "pose" not in self.effect.channels:
            return position, quaternion
        if not isinstance(self.effect, PoseDelay):
            p, q = self.effect.measured_pose(np.array([t]), position[None], quaternion[None])
            return p[0], q[0]
        self._history.append((t, np.array(position), np.array(quaternion)))
        h = self._history[-64:]
        p, q = self.effect.measured_pose(np.array([x[0] for x in h]), np.array([x[1] for x in h]),
                                         np.array([x[2] for x in h]))
        return p[-1], q[-1]


class HiddenWrench(HiddenEffect):
    """A hidden catalogue effect with a wrench channel (evaluated every physics step)."""

    def wrench(self, t, x, n):
        inputs = EffectInputs(np.array([t]), x[None, 0:3], x[None, 6:10], x[None, 3:6],
                              x[None, 10:13], n[None, :], self._theta, self._rotors)
        f, m = self.effect.wrench(inputs)
        return f[0], m[0]


def hidden(effect: ModelEffect, config: VehicleConfig) -> tuple[VehicleConfig, list[TruthEffect]]:
    """The truth config and the truth effects that hide ``effect`` from the model."""
    if isinstance(effect, MotorLag):
        cfg = replace(config, motor=replace(config.motor, time_constant=float(effect.values[0])))
        return cfg, [HiddenEffect(effect, cfg, cfg.theta)]
    cls = HiddenWrench if "wrench" in effect.channels else HiddenEffect
    return config, [cls(effect, config, config.theta)]
