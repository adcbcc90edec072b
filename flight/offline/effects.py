"""Truth-side effects: what the simulated world does that the model may not know.

The simulator integrates the model's dynamics (`mavsysid.vehicle.dynamics`) and lets a list of
`TruthEffect` objects add to it, each through up to three hooks:

* `TruthEffect.wrench` — an extra body-frame force and torque (aerodynamics, wind,
  a centre-of-gravity offset, thrust drifting with battery sag, ground effect …),
  held constant over one physics step;
* `TruthEffect.measure_pose` — corrupt what the motion-capture system reports
  (delay, marker offset …);
* `TruthEffect.logged_rotor_speeds` — change what the log reports as rotor speeds
  (e.g. commanded instead of actual speeds when the motor lag is hidden);

and `TruthEffect.motor_time_constant` may replace the config's motor time constant.

An effect overrides only the hooks it needs; the simulator keeps its fast path when no
effect applies a wrench. Effects are truth only: they are recorded in a simulated
flight's metadata, never passed to estimation.

`CatalogEffect` makes any effect of the catalogue (`mavsysid.vehicle.model_effects`) act on the
truth with exactly the catalogue's physics; `hidden_effect` wraps one the model does not
know, e.g. for the offline simulator (`mavsysid.flight.offline.simulator`)::

    effect = hidden_effect(parse_effect("motor_lag:tau=0.04"))
    Simulator(config, settings=SimulationSettings(seed=1), effects=[effect]).run(traj, dir)

A vehicle config's own ``[effects.NAME]`` tables are known physics: the simulators add
them as ``CatalogEffect(effect, hidden=False)`` themselves (`config_truth_effects`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from mavsysid.vehicle.model_effects import (
    EffectInputs,
    ModelEffect,
    MotorLag,
    PoseDelay,
    RotorInertia,
    RotorSpeedLag,
)
from mavsysid.vehicle.rotation import rotation_kernel

if TYPE_CHECKING:
    from mavsysid.vehicle.config import VehicleConfig

__all__ = [
    "CatalogEffect",
    "ConstantWrench",
    "ProcessNoise",
    "TruthEffect",
    "applies_wrench",
    "config_truth_effects",
    "effect_metadata",
    "hidden_effect",
    "motor_time_constant",
]


class TruthEffect:
    """Base class of truth-side effects; every hook defaults to 'no effect'."""

    #: Stable identifier (docs/architecture.md effect names where one applies).
    name: str = "effect"
    #: True: `wrench` is evaluated once per control tick and held over its physics
    #: steps (smooth effects; a numpy evaluation per physics step would be slow).
    #: False: evaluated every physics step (e.g. white process noise).
    wrench_per_tick: ClassVar[bool] = False
    #: Whether the model is unaware of the effect (recorded under ``truth.effects``).
    hidden: bool = True

    def parameters(self) -> dict[str, float | list[float]]:
        """The effect's parameters, for the flight metadata."""
        return {}

    def reset(self, physics_dt: float) -> None:
        """Forget any internal state before a new flight; ``physics_dt`` is the step, s.

        Parameters
        ----------
        physics_dt : float
            Physics step, s.
        """

    def bind(self, true_theta: np.ndarray, rotor_positions: np.ndarray,
             rotor_directions: np.ndarray | None = None) -> None:
        """Learn the truth's θ (6,), rotor hubs (k, 3), m, and spin directions (k,).

        Parameters
        ----------
        true_theta : ndarray, shape (6,)
            The truth's θ, SI.
        rotor_positions : ndarray, shape (k, 3)
            Rotor hubs, m, body FLU.
        rotor_directions : ndarray, shape (k,), optional
            Spin directions, +1 counter-clockwise seen from above, −1 clockwise.
        """

    def motor_time_constant(self) -> float | None:
        """The truth's motor time constant, s, if this effect sets it (else None)."""
        return None

    def wrench(
        self, t: float, x: np.ndarray, n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Extra body force (N, (3,)) and torque (N·m, (3,)) at time t, state x, speeds n.

        Parameters
        ----------
        t : float
            Time since the flight started, s.
        x : ndarray, shape (13,)
            True state [p, v_B, q, ω].
        n : ndarray, shape (k,)
            Actual rotor speeds, rad/s.
        """
        return None

    def measure_pose(
        self, t: float, position: np.ndarray, quaternion: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The pose the motion-capture system reports, given the true one.

        Parameters
        ----------
        t : float
            Time, s.
        position : ndarray, shape (3,)
            True position, m, world ENU.
        quaternion : ndarray, shape (4,)
            True attitude [w, x, y, z].
        """
        return position, quaternion

    def logged_rotor_speeds(
        self, t: float, actual: np.ndarray, commanded: np.ndarray
    ) -> np.ndarray:
        """The rotor speeds the log reports (rad/s, (k,)).

        Parameters
        ----------
        t : float
            Time, s.
        actual : ndarray, shape (k,)
            Actual (lagged) rotor speeds, rad/s.
        commanded : ndarray, shape (k,)
            Commanded rotor speeds, rad/s.
        """
        return actual


def applies_wrench(effect: TruthEffect) -> bool:
    """True when ``effect`` adds a force or torque to the truth.

    Parameters
    ----------
    effect : TruthEffect
        The effect.
    """
    if isinstance(effect, CatalogEffect):
        return "wrench" in effect.effect.channels
    return type(effect).wrench is not TruthEffect.wrench


def motor_time_constant(effects: Sequence[TruthEffect], default: float) -> float:
    """The truth's motor time constant, s: the last effect that sets one, else ``default``.

    Parameters
    ----------
    effects : sequence of TruthEffect
        The truth's effects.
    default : float
        The config's motor time constant, s.
    """
    tau = default
    for effect in effects:
        value = effect.motor_time_constant()
        if value is not None:
            tau = value
    return tau


def effect_metadata(effect: TruthEffect) -> dict:
    """How an effect is recorded in a flight's meta.json: name, parameters, hidden.

    Parameters
    ----------
    effect : TruthEffect
        The effect.
    """
    return {"name": effect.name, "parameters": effect.parameters(), "hidden": effect.hidden}


@dataclass(frozen=True)
class _OneSample(EffectInputs):
    """`EffectInputs` of one sample whose rotation was computed on plain floats."""

    matrix: np.ndarray | None = None

    def rotation(self) -> np.ndarray:
        return self.matrix  # type: ignore[return-value]


class CatalogEffect(TruthEffect):
    """An effect of the catalogue (`mavsysid.vehicle.model_effects`) acting on the truth.

    Every channel of the catalogue effect is used: its ``wrench`` (evaluated once per
    control tick on the true state, actual rotor speeds, true θ and the time since the
    flight started), its ``measured_pose`` (a delay interpolates a history of the true
    poses passed to `measure_pose`), and its rotor-speed channel (a `MotorLag` makes the
    truth's motors lag with its tau and the log report the commanded speeds; a
    `RotorSpeedLag` makes the log report a first-order lag of the actual speeds). A
    `RotorInertia` sees ṅ as the change of the actual speeds since the previous tick.

    Parameters
    ----------
    effect : ModelEffect
        The catalogue effect with its parameter values.
    hidden : bool
        True: the model does not know it (a hidden truth); False: a known effect of the
        vehicle config.
    """

    wrench_per_tick = True

    def __init__(self, effect: ModelEffect, hidden: bool = True) -> None:
        self.effect = effect
        self.name = effect.name
        self.hidden = hidden
        self._theta = np.full(6, np.nan)
        self._rotors = np.zeros((0, 3))
        self._directions: np.ndarray | None = None
        self._history: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
        self._last_speeds: tuple[float, np.ndarray] | None = None
        self._lagged: tuple[float, np.ndarray, np.ndarray] | None = None

    def __repr__(self) -> str:
        return f"CatalogEffect({self.effect!r}, hidden={self.hidden})"

    def parameters(self) -> dict[str, float | list[float]]:
        return dict(self.effect.as_dict())

    def bind(self, true_theta: np.ndarray, rotor_positions: np.ndarray,
             rotor_directions: np.ndarray | None = None) -> None:
        self._theta = np.asarray(true_theta, dtype=float).reshape(6).copy()
        self._rotors = np.ascontiguousarray(rotor_positions, dtype=float)
        self._directions = (None if rotor_directions is None
                            else np.asarray(rotor_directions, dtype=float).copy())

    def reset(self, physics_dt: float) -> None:
        self._history.clear()
        self._last_speeds = None
        self._lagged = None

    def motor_time_constant(self) -> float | None:
        if isinstance(self.effect, MotorLag):
            return max(float(self.effect.values[0]), 0.0)
        return None

    def inputs(self, t: float, x: np.ndarray, n: np.ndarray) -> EffectInputs:
        """The one-sample `EffectInputs` of time t (s), state x (13,) and speeds n (k,).

        Parameters
        ----------
        t : float
            Time since the flight started, s.
        x : ndarray, shape (13,)
            True state [p, v_B, q, ω].
        n : ndarray, shape (k,)
            Actual rotor speeds, rad/s.
        """
        rates = None
        if isinstance(self.effect, RotorInertia):
            # ṅ over the last tick: the wrench is held over the tick's physics steps.
            last, self._last_speeds = self._last_speeds, (t, np.array(n, dtype=float))
            rates = np.zeros((1, len(n)))
            if last is not None and t > last[0]:
                rates[0] = (n - last[1]) / (t - last[0])
        return _OneSample(np.array([t]), x[None, 0:3], x[None, 6:10], x[None, 3:6],
                          x[None, 10:13], n[None, :], self._theta, self._rotors,
                          rotor_directions=self._directions, rotor_speed_rates=rates,
                          matrix=rotation_kernel(x[6:10])[None])

    def wrench(
        self, t: float, x: np.ndarray, n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        if "wrench" not in self.effect.channels:
            return None
        force, torque = self.effect.wrench(self.inputs(t, x, n))
        return force[0], torque[0]

    def measure_pose(
        self, t: float, position: np.ndarray, quaternion: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        if "pose" not in self.effect.channels:
            return position, quaternion
        if not isinstance(self.effect, PoseDelay):
            p, q = self.effect.measured_pose(np.array([t]), position[None], quaternion[None])
            return p[0], q[0]
        # The catalogue interpolates over a pose history: keep just enough of it (the
        # newest sample at or before t - delay, and everything after).
        history = self._history
        history.append((t, np.array(position, dtype=float), np.array(quaternion, dtype=float)))
        horizon = t - abs(float(self.effect.values[0]))
        while len(history) > 2 and history[1][0] <= horizon:
            history.popleft()
        ts = np.array([h[0] for h in history])
        p, q = self.effect.measured_pose(ts, np.array([h[1] for h in history]),
                                         np.array([h[2] for h in history]))
        return p[-1], q[-1]

    def logged_rotor_speeds(
        self, t: float, actual: np.ndarray, commanded: np.ndarray
    ) -> np.ndarray:
        if isinstance(self.effect, RotorSpeedLag):
            return self._lag(t, np.array(actual, dtype=float))
        if "rotor_speeds" in self.effect.channels:
            return np.array(commanded, dtype=float)
        return actual

    def _lag(self, t: float, actual: np.ndarray) -> np.ndarray:
        """One step of the sensor's first-order lag (the catalogue's recursion, input
        linear between log samples)."""
        if self._lagged is None or t <= self._lagged[0]:
            self._lagged = (t, actual, actual)
            return actual
        t0, x0, y0 = self._lagged
        y = self.effect.logged_step(t - t0, y0, x0, actual)  # type: ignore[attr-defined]
        self._lagged = (t, actual, y)
        return y


def hidden_effect(effect: ModelEffect) -> CatalogEffect:
    """A catalogue effect as hidden truth: the model (and the vehicle config) do not know it.

    Parameters
    ----------
    effect : ModelEffect
        The catalogue effect with its values.
    """
    return CatalogEffect(effect, hidden=True)


def config_truth_effects(config: VehicleConfig) -> list[CatalogEffect]:
    """The vehicle config's known effects (``[effects.NAME]``) as truth-side physics.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle, with its ``[effects.NAME]`` tables.
    """
    return [CatalogEffect(e, hidden=False) for e in getattr(config, "effects", ())]


@dataclass
class ConstantWrench(TruthEffect):
    """A constant extra force and torque in the body frame (e.g. a tether, a payload).

    Attributes
    ----------
    force : ndarray, shape (3,)
        N, body FLU.
    torque : ndarray, shape (3,)
        N·m, body FLU.
    name : str
        The effect's name in ``meta.json``.
    """

    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    name: str = "constant_wrench"

    def parameters(self) -> dict[str, float | list[float]]:
        return {"force": [float(v) for v in self.force], "torque": [float(v) for v in self.torque]}

    def wrench(
        self, t: float, x: np.ndarray, n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        return np.asarray(self.force, dtype=float), np.asarray(self.torque, dtype=float)


@dataclass
class ProcessNoise(TruthEffect):
    """White force and moment noise on the body: the estimator's process-noise model made true.

    Continuous white noise of density q held over one physics step dt is a constant of
    σ = q / √dt, drawn anew every step.

    Attributes
    ----------
    force_density : float
        N·√s, per body axis.
    moment_density : float
        N·m·√s, per body axis.
    seed : int
    name : str
        The effect's name in ``meta.json``.
    """

    force_density: float
    moment_density: float
    seed: int = 0
    name: str = "process_noise"

    def parameters(self) -> dict[str, float | list[float]]:
        return {"force_density": self.force_density, "moment_density": self.moment_density,
                "seed": float(self.seed)}

    def reset(self, physics_dt: float) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._sigma = np.repeat([self.force_density, self.moment_density], 3) / np.sqrt(
            physics_dt)
        self._block = np.empty((0, 6))
        self._next = 0

    def wrench(
        self, t: float, x: np.ndarray, n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        if self._next == len(self._block):  # draw in blocks: one call per step is slow
            self._block = self._rng.normal(size=(4096, 6)) * self._sigma
            self._next = 0
        w = self._block[self._next]
        self._next += 1
        return w[:3], w[3:]
