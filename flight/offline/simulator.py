"""The offline simulator: truth dynamics at ≥ 500 Hz, the controller, and a pose log.

The truth integrates the model's own dynamics kernel (`mavsysid.vehicle.dynamics`) with RK4,
with first-order motor lag on the rotor speeds (the config's `[motor].time_constant`)
and any `TruthEffect` objects. The controller runs at its own rate with perfect state
feedback, holding its commands between ticks. At the log rate the simulator records
what a motion-capture system and ESC telemetry would report: pose with noise, and the
actual (lagged) rotor speeds, into ``pose.csv``; and the true state into ``truth.csv``.

Model effects (`mavsysid.vehicle.model_effects`) act on the truth in two ways: the vehicle
config's ``[effects.NAME]`` tables are known physics, always simulated (meta.json
``model_effects``); hidden ones are passed as ``effects`` (meta.json ``truth.effects``
with ``"hidden": true``). A hidden-effect flight in three lines::

    effect = hidden_effect(parse_effect("wind:x=2"))  # offline.effects, model_effects
    sim = Simulator(config, true_theta=theta, settings=SimulationSettings(seed=1),
                    effects=[effect])
    result = sim.run(trajectory, directory)  # pose.csv, truth.csv and meta.json

Effect wrenches see t = time since the flight start (as in the logs), the true state,
the actual rotor speeds and the true θ; catalogue wrenches are evaluated once per
control tick and held over its physics steps, like the rotor commands.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np
from mavsysid.flight.offline.controller import GeometricController, reference_samples
from mavsysid.flight.offline.effects import (
    TruthEffect,
    applies_wrench,
    config_truth_effects,
    effect_metadata,
    motor_time_constant,
)
from mavsysid.formats.flight_log import FlightRecorder
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.dynamics import ATT, POS, STATE_DIM, derivative_kernel
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.rotation import quat_exp
from mavsysid.vehicle.trajectory import Trajectory

from mavsysid.errors import InputError

__all__ = ["SimulationResult", "SimulationSettings", "Simulator"]

_REFERENCE_BLOCK_S = 10.0


@dataclass(frozen=True)
class SimulationSettings:
    """Rates, noise switches and seed of a simulated flight.

    Attributes
    ----------
    physics_rate, control_rate, log_rate : float
        Hz. The physics rate must be a whole multiple of the control rate, and the
        control rate a whole multiple of the log rate.
    motor_lag : bool
        Apply the config's motor time constant on the truth side.
    sensor_noise : bool
        Add the config's motion-capture and rotor-speed noise to the log.
    seed : int
        Seed of the noise generator.
    """

    physics_rate: float = 1000.0
    control_rate: float = 500.0
    log_rate: float = 100.0
    motor_lag: bool = True
    sensor_noise: bool = True
    seed: int = 0

    def steps(self) -> tuple[int, int]:
        """(physics steps per control tick, control ticks per log sample)."""
        per_control = self.physics_rate / self.control_rate
        per_log = self.control_rate / self.log_rate
        if self.physics_rate < 500.0:
            raise InputError(f"physics rate {self.physics_rate:g} Hz: expected at least 500 Hz")
        for name, ratio in (("physics/control", per_control), ("control/log", per_log)):
            if ratio < 1.0 or abs(ratio - round(ratio)) > 1e-9:
                raise InputError(f"rates: {name} must be a whole number ≥ 1, got {ratio:g}")
        return round(per_control), round(per_log)


@dataclass(frozen=True)
class SimulationResult:
    """What a simulated flight produced, at the log rate (S samples).

    Attributes
    ----------
    times : ndarray, shape (S,)
        s.
    states : ndarray, shape (S, 13)
        True states [p, v_B, q, ω].
    rotor_speeds : ndarray, shape (S, k)
        True (lagged) rotor speeds, rad/s.
    commands : ndarray, shape (S, k)
        Commanded rotor speeds, rad/s.
    reference_position : ndarray, shape (S, 3)
        Reference position, m.
    saturated_fraction : float
        Fraction of control ticks with a rotor command clipped at a limit.
    wall_time : float
        Seconds of computer time the run took.
    directory : Path or None
        Where the logs went.
    """

    times: np.ndarray
    states: np.ndarray
    rotor_speeds: np.ndarray
    commands: np.ndarray
    reference_position: np.ndarray
    saturated_fraction: float
    wall_time: float
    directory: Path | None = None

    @property
    def position_rms(self) -> float:
        """Root-mean-square 3-D tracking error of the true position, m."""
        err = self.states[:, POS] - self.reference_position
        return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per second of computer time."""
        return float(self.times[-1] - self.times[0]) / max(self.wall_time, 1e-12)


@numba.njit(cache=True)
def _advance(y, n_cmd, dt, steps, tau, theta, mass, r, eps, force, torque):
    """Advance the truth state y = [x (13), n (k)] by ``steps`` RK4 steps in place."""
    nx = 13
    dim = y.shape[0]
    k1 = np.empty(dim)
    k2 = np.empty(dim)
    k3 = np.empty(dim)
    k4 = np.empty(dim)
    tmp = np.empty(dim)
    if tau <= 0.0:
        y[nx:] = n_cmd
    for _ in range(steps):
        for stage in range(4):
            if stage == 0:
                tmp[:] = y
                kk = k1
            elif stage == 1:
                tmp[:] = y + 0.5 * dt * k1
                kk = k2
            elif stage == 2:
                tmp[:] = y + 0.5 * dt * k2
                kk = k3
            else:
                tmp[:] = y + dt * k3
                kk = k4
            derivative_kernel(tmp[:nx], tmp[nx:], theta, mass, r, eps, force, torque, kk[:nx])
            if tau > 0.0:
                kk[nx:] = (n_cmd - tmp[nx:]) / tau
            else:
                kk[nx:] = 0.0
        y += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        q = y[6:10]
        y[6:10] = q / np.sqrt(np.sum(q * q))


@dataclass
class Simulator:
    """Flies trajectories in simulation.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle; its nominal θ is the controller's model.
    true_theta : ndarray, shape (6,), optional
        The truth's θ; the config's nominal θ by default.
    settings : SimulationSettings, optional
    controller : GeometricController, optional
        Default: a `GeometricController` on the config's nominal θ.
    effects : sequence of TruthEffect
        Extra truth-side effects, hidden from the model (e.g.
        `mavsysid.flight.offline.effects.hidden_effect`).
        The config's own ``effects`` are simulated too, before these (`truth_effects`).
    """

    config: VehicleConfig
    true_theta: np.ndarray | None = None
    settings: SimulationSettings = field(default_factory=SimulationSettings)
    controller: GeometricController | None = None
    effects: Sequence[TruthEffect] = ()

    def __post_init__(self) -> None:
        self.true_theta = (
            self.config.theta.copy() if self.true_theta is None
            else np.asarray(self.true_theta, dtype=float).reshape(6)
        )
        if self.controller is None:
            self.controller = GeometricController(self.config)
        self.truth_effects: list[TruthEffect] = [*config_truth_effects(self.config),
                                                 *self.effects]

    def run(
        self,
        trajectory: Trajectory,
        directory: Path | None = None,
        progress: Callable[[float, float], None] | None = None,
        description: dict | None = None,
    ) -> SimulationResult:
        """Fly ``trajectory`` from rest at its start; log into ``directory`` if given.

        Parameters
        ----------
        trajectory : Trajectory
        directory : Path, optional
            Flight directory for ``pose.csv``, ``truth.csv`` and ``meta.json``.
        progress : callable, optional
            Called as ``progress(t, duration)`` about once per simulated second.
        description : dict, optional
            Stored under ``trajectory`` in the flight metadata.

        Returns
        -------
        SimulationResult
        """
        s = self.settings
        per_control, per_log = s.steps()
        cfg = self.config
        k = cfg.rotor_count
        dt = 1.0 / s.physics_rate
        n_control = round(trajectory.duration * s.control_rate)
        # References are computed in blocks so that long flights need little memory.
        block = max(per_log, round(_REFERENCE_BLOCK_S * s.control_rate) // per_log * per_log)
        start = flat_to_state(trajectory.flat_outputs(np.array([0.0])), cfg, self.true_theta)

        y = np.concatenate([start.states()[0], start.rotor_speeds[0]])
        y[3:6] = 0.0
        n_cmd = start.rotor_speeds[0].copy()
        effects = self.truth_effects
        tau = self._motor_time_constant()
        args = (self.true_theta, float(cfg.mass), np.ascontiguousarray(cfg.rotor_positions),
                np.ascontiguousarray(cfg.rotor_directions))
        tick_effects = [e for e in effects if applies_wrench(e) and e.wrench_per_tick]
        step_effects = [e for e in effects if applies_wrench(e) and not e.wrench_per_tick]
        for effect in effects:
            effect.bind(self.true_theta, cfg.rotor_positions)
            effect.reset(dt)
        zero = np.zeros(3)
        noise = _SensorNoise(cfg, s.seed, enabled=s.sensor_noise)
        n_log = n_control // per_log + 1
        log = _LogBuffers(n_log, k)
        recorder = None
        if directory is not None:
            recorder = FlightRecorder(directory, cfg, k)
            recorder.start(self._metadata(trajectory, description))

        # Load (or compile) the kernels before the clock starts, so wall_time is simulation.
        self.controller.command(y[:STATE_DIM].copy(), reference_samples(
            trajectory, np.zeros(1), cfg)[0], n_cmd.copy())
        _advance(y.copy(), n_cmd, dt, 0, tau, *args, zero, zero)
        saturated = 0
        wall0 = time.perf_counter()
        try:
            for i in range(n_control + 1):
                t = i / s.control_rate
                if i % block == 0:
                    ticks = np.arange(i, min(i + block, n_control + 1)) / s.control_rate
                    reference = reference_samples(trajectory, ticks, cfg)
                ref = reference[i % block]
                if i % per_log == 0:
                    row = i // per_log
                    log.store(row, t, y, n_cmd, ref[0:3])
                    if recorder is not None:
                        self._record(recorder, noise, t, y, n_cmd, ref)
                    if progress is not None and row % int(s.log_rate) == 0:
                        progress(t, trajectory.duration)
                if i == n_control:
                    break
                saturated += self.controller.command(y[:STATE_DIM], ref, n_cmd)
                held = zero, zero
                if tick_effects:
                    held = _effect_wrench(tick_effects, t, y)
                if not step_effects:
                    _advance(y, n_cmd, dt, per_control, tau, *args, *held)
                    continue
                for j in range(per_control):
                    force, torque = _effect_wrench(step_effects, t + j * dt, y)
                    _advance(y, n_cmd, dt, 1, tau, *args, force + held[0], torque + held[1])
        except BaseException:
            if recorder is not None:
                recorder.finish(status="aborted")
            raise
        wall = time.perf_counter() - wall0
        result = SimulationResult(
            times=log.t, states=log.x, rotor_speeds=log.n, commands=log.n_cmd,
            reference_position=log.ref, saturated_fraction=saturated / max(n_control, 1),
            wall_time=wall, directory=directory,
        )
        if recorder is not None:
            recorder.finish(status="complete", summary={
                "position_rms_m": result.position_rms,
                "saturated_fraction": result.saturated_fraction,
            })
        return result

    def _motor_time_constant(self) -> float:
        """The truth's motor lag, s: an effect's (a motor_lag) or the config's."""
        default = self.config.motor.time_constant if self.settings.motor_lag else 0.0
        return motor_time_constant(self.truth_effects, default)

    def _record(
        self, recorder: FlightRecorder, noise: _SensorNoise, t: float, y: np.ndarray,
        n_cmd: np.ndarray, reference: np.ndarray,
    ) -> None:
        """Write what the sensors would report, and the truth, at one log time."""
        x = y[:STATE_DIM]
        n = y[STATE_DIM:]
        position, quaternion = x[POS].copy(), x[ATT].copy()
        logged_n = n.copy()
        for effect in self.truth_effects:
            position, quaternion = effect.measure_pose(t, position, quaternion)
            logged_n = effect.logged_rotor_speeds(t, logged_n, n_cmd)
        position, quaternion, logged_n = noise.apply(position, quaternion, logged_n)
        recorder.record(t, position, quaternion, logged_n, reference, x, n, n_cmd)

    def _metadata(self, trajectory: Trajectory, description: dict | None) -> dict:
        s = self.settings
        return {
            "simulated": True,
            "seed": s.seed,
            "rates_hz": {"physics": s.physics_rate, "control": s.control_rate, "log": s.log_rate},
            "sensor_noise": s.sensor_noise,
            "trajectory": {"duration_s": trajectory.duration, **(description or {})},
            "truth": {
                "parameters": dict(zip(
                    ("c_T", "c_D", "c_M", "j_x", "j_y", "j_z"),
                    (float(v) for v in self.true_theta), strict=True,
                )),
                "motor_time_constant_s": self._motor_time_constant(),
                # Hidden from the model: what a diagnosis should find. Estimation reads
                # only truth.parameters, and only to report errors.
                "effects": [effect_metadata(e) for e in self.truth_effects if e.hidden],
            },
            "model_effects": [effect_metadata(e) for e in self.truth_effects if not e.hidden],
        }


def _effect_wrench(
    effects: list[TruthEffect], t: float, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Summed extra body force (N) and torque (N·m) of ``effects`` at truth y = [x, n]."""
    force = np.zeros(3)
    torque = np.zeros(3)
    for effect in effects:
        w = effect.wrench(t, y[:STATE_DIM], y[STATE_DIM:])
        if w is not None:
            force += w[0]
            torque += w[1]
    return force, torque


class _LogBuffers:
    """In-memory copy of the truth at the log rate, returned to library callers."""

    def __init__(self, size: int, k: int) -> None:
        self.t = np.empty(size)
        self.x = np.empty((size, STATE_DIM))
        self.n = np.empty((size, k))
        self.n_cmd = np.empty((size, k))
        self.ref = np.empty((size, 3))

    def store(self, row: int, t: float, y: np.ndarray, n_cmd: np.ndarray, ref: np.ndarray) -> None:
        self.t[row] = t
        self.x[row] = y[:STATE_DIM]
        self.n[row] = y[STATE_DIM:]
        self.n_cmd[row] = n_cmd
        self.ref[row] = ref


class _SensorNoise:
    """Motion-capture and rotor-speed noise, drawn in vectorised blocks from one seed.

    Position gets N(0, σ_p² I), attitude q ⊗ Exp(φ) with φ ~ N(0, σ_φ² I) (body frame),
    rotor speeds N(0, σ_n² I).
    """

    _BLOCK = 1000

    def __init__(self, config: VehicleConfig, seed: int, enabled: bool) -> None:
        self._rng = np.random.default_rng(seed)
        self._noise = config.noise
        self._k = config.rotor_count
        self._enabled = enabled
        self._next = self._BLOCK

    def _draw(self) -> None:
        nz, b = self._noise, self._BLOCK
        self._dp = self._rng.normal(0.0, nz.position_sigma, (b, 3))
        self._dq = quat_exp(self._rng.normal(0.0, nz.attitude_sigma, (b, 3))).tolist()
        self._dn = self._rng.normal(0.0, nz.rotor_speed_sigma, (b, self._k))
        self._next = 0

    def apply(
        self, position: np.ndarray, quaternion: np.ndarray, rotor_speeds: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noisy copies of a true pose and rotor speeds."""
        if not self._enabled:
            return position, quaternion, rotor_speeds
        if self._next == self._BLOCK:
            self._draw()
        i = self._next
        self._next += 1
        # One Hamilton product on plain floats: numpy's per-call overhead would dominate.
        aw, ax, ay, az = quaternion.tolist()
        bw, bx, by, bz = self._dq[i]
        q = np.array([
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ])
        return position + self._dp[i], q, rotor_speeds + self._dn[i]
