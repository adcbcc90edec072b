"""A pose from an on-board state estimator instead of motion capture: lagged, smoothed, correlated.

Small vehicles are often logged with the pose their own estimator reports, not a
motion-capture one. `OnboardPoseEstimate` is a truth-side effect (through
`TruthEffect.measure_pose`) that turns the true pose into such an estimate, in three steps
applied at every log sample:

1. a pure delay (the estimator's latency), by interpolating a history of true poses;
2. a first-order low pass of time constant τ (the estimator's smoothing): position
   p̂ ← p̂ + α (p − p̂), attitude q̂ ← q̂ ⊗ Exp(α Log(q̂⁻¹ q)), α = 1 − exp(−Δt/τ);
3. correlated noise: a first-order Gauss–Markov process per axis (correlation time T_c,
   stationary σ), e ← a e + √(1 − a²) σ ν with a = exp(−Δt/T_c), ν ~ N(0, 1).

The simulator's white motion-capture noise (`mavsysid.flight.offline.sensor_noise`) is
still added afterwards when the settings ask for it. Timestamp jitter and dropped samples
are a property of the logger: `mavsysid.flight.offline.log_timing`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.flight.offline.effects import TruthEffect
from mavsysid.vehicle.rotation import exp_tuple, multiply_tuple, normalized_tuple, slerp_tuple

__all__ = ["OnboardPoseEstimate"]


_BLOCK = 4096


@numba.njit(cache=True)
def _interpolate(t0, p0, q0, t1, p1, q1, target, out):
    """The pose at ``target`` between two samples into ``out`` (7,): [p, q] (at t0 before)."""
    s = 0.0 if target <= t0 else min((target - t0) / (t1 - t0), 1.0)
    out[0:3] = p0 + s * (p1 - p0)
    out[3:7] = slerp_tuple(q0, q1, s)


@numba.njit(cache=True)
def _estimator_step(state, pose, alpha, a, sigma, nu, first, out):
    """One sample of the low pass and Gauss–Markov noise (see the module docstring).

    state (13,): [p̂, q̂, e] updated in place; pose (7,): the delayed true pose; sigma,
    nu (6,): stationary σ and standard normal draws; out (7,): the reported [p, q].
    """
    if first:  # the estimator starts converged on the first pose
        state[0:7] = pose
        state[7:13] = sigma * nu
    else:
        state[0:3] += alpha * (pose[0:3] - state[0:3])
        state[3:7] = normalized_tuple(slerp_tuple(state[3:7], pose[3:7], alpha))
        state[7:13] = a * state[7:13] + np.sqrt(1.0 - a * a) * sigma * nu
    out[0:3] = state[0:3] + state[7:10]
    out[3:7] = normalized_tuple(multiply_tuple(state[3:7], exp_tuple(state[10:13])))


@dataclass
class OnboardPoseEstimate(TruthEffect):
    """The pose an on-board estimator reports: delayed, low-passed, with correlated noise.

    Attributes
    ----------
    delay : float
        s, the estimator's latency (≥ 0).
    time_constant : float
        s, τ of the first-order smoothing (0: none).
    position_sigma : float
        m, stationary σ of the correlated position noise, per axis.
    attitude_sigma : float
        rad, stationary σ of the correlated attitude noise (body-frame rotation vector),
        per axis.
    correlation_time : float
        s, T_c of the Gauss–Markov noise (> 0).
    seed : int
        Seed of the noise generator.
    name : str
        The effect's name in ``meta.json``.
    """

    delay: float = 0.02
    time_constant: float = 0.015
    position_sigma: float = 0.005
    attitude_sigma: float = 0.0175
    correlation_time: float = 0.2
    seed: int = 0
    name: str = "onboard_pose"

    def __post_init__(self) -> None:
        if self.delay < 0.0 or self.time_constant < 0.0 or self.correlation_time <= 0.0:
            raise ValueError("delay and time_constant must be ≥ 0 and correlation_time > 0")
        self.reset(0.0)

    def parameters(self) -> dict[str, float | list[float]]:
        return {"delay": self.delay, "time_constant": self.time_constant,
                "position_sigma": self.position_sigma, "attitude_sigma": self.attitude_sigma,
                "correlation_time": self.correlation_time, "seed": float(self.seed)}

    def reset(self, physics_dt: float) -> None:
        self._history: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
        self._rng = np.random.default_rng(self.seed)
        self._draws = np.empty((0, 6))
        self._next = 0
        self._last_t: float | None = None
        self._state = np.zeros(13)
        self._sigma = np.repeat([self.position_sigma, self.attitude_sigma], 3).astype(float)

    def _delayed(self, t: float, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The true pose [p, q] (7,) ``delay`` s ago (the oldest one until that exists)."""
        history = self._history
        history.append((t, np.array(p, dtype=float), np.array(q, dtype=float)))
        target = t - self.delay
        while len(history) > 2 and history[1][0] <= target:
            history.popleft()
        t0, p0, q0 = history[0]
        t1, p1, q1 = history[1] if len(history) > 1 else history[0]
        pose = np.empty(7)
        if t1 <= t0:
            pose[0:3], pose[3:7] = p0, q0
        else:
            _interpolate(t0, p0, q0, t1, p1, q1, target, pose)
        return pose

    def measure_pose(
        self, t: float, position: np.ndarray, quaternion: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        pose = self._delayed(t, position, quaternion)
        if self._next == len(self._draws):  # draw in blocks: one call per sample is slow
            self._draws = self._rng.normal(size=(_BLOCK, 6))
            self._next = 0
        nu = self._draws[self._next]
        self._next += 1
        dt = 0.0 if self._last_t is None else max(t - self._last_t, 0.0)
        alpha = 1.0 if self.time_constant == 0.0 else -math.expm1(-dt / self.time_constant)
        out = np.empty(7)
        _estimator_step(self._state, pose, alpha, math.exp(-dt / self.correlation_time),
                        self._sigma, nu, self._last_t is None, out)
        self._last_t = t
        return out[0:3], out[3:7]
