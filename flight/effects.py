"""Truth-side effects: what the simulated world does that the model may not know.

The simulator integrates the model's dynamics (`vehicle.dynamics`) and lets a list of
`TruthEffect` objects add to it, each through up to three hooks:

* `TruthEffect.wrench` — an extra body-frame force and torque (aerodynamics, wind,
  a centre-of-gravity offset, thrust drifting with battery sag, ground effect …),
  held constant over one physics step;
* `TruthEffect.measure_pose` — corrupt what the motion-capture system reports
  (delay, marker offset …);
* `TruthEffect.logged_rotor_speeds` — change what the log reports as rotor speeds
  (e.g. commanded instead of actual speeds when the motor lag is hidden).

An effect overrides only the hooks it needs; the simulator keeps its fast path when no
effect overrides `wrench`. Effects are truth only: they are recorded in a simulated
flight's metadata, never passed to estimation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ConstantWrench", "ProcessNoise", "TruthEffect", "applies_wrench"]


class TruthEffect:
    """Base class of truth-side effects; every hook defaults to 'no effect'."""

    #: Stable identifier (DESIGN.md effect names where one applies).
    name: str = "effect"

    def parameters(self) -> dict[str, float | list[float]]:
        """The effect's parameters, for the flight metadata."""
        return {}

    def reset(self, physics_dt: float) -> None:
        """Forget any internal state before a new flight; ``physics_dt`` is the step, s."""

    def wrench(
        self, t: float, x: np.ndarray, n: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Extra body force (N, (3,)) and torque (N·m, (3,)) at time t, state x, speeds n."""
        return None

    def measure_pose(
        self, t: float, position: np.ndarray, quaternion: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The pose the motion-capture system reports, given the true one."""
        return position, quaternion

    def logged_rotor_speeds(
        self, t: float, actual: np.ndarray, commanded: np.ndarray
    ) -> np.ndarray:
        """The rotor speeds the log reports (rad/s, (k,))."""
        return actual


def applies_wrench(effect: TruthEffect) -> bool:
    """True when ``effect`` overrides `TruthEffect.wrench`."""
    return type(effect).wrench is not TruthEffect.wrench


@dataclass
class ConstantWrench(TruthEffect):
    """A constant extra force and torque in the body frame (e.g. a tether, a payload).

    Attributes
    ----------
    force : ndarray, shape (3,)
        N, body FLU.
    torque : ndarray, shape (3,)
        N·m, body FLU.
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
