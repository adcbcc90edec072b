"""The offline simulator: truth dynamics at ≥ 500 Hz, the controller, and a pose log.

The truth integrates the model's own dynamics kernel (`mavsysid.vehicle.dynamics`) with RK4,
with first-order motor lag on the rotor speeds (the config's `[motor].time_constant`)
and any `TruthEffect` objects (`mavsysid.flight.offline.truth_step`). The controller runs
at its own rate with perfect state feedback, holding its commands between ticks. At the
log rate the simulator records what a motion-capture system, ESC telemetry and the
vehicle's IMU would report: pose with noise (`mavsysid.flight.offline.sensor_noise`), the
actual (lagged) rotor speeds, and the gyro and specific force with noise and constant
biases (`mavsysid.flight.offline.imu_sensor`), into ``pose.csv``; and the true state and
the true IMU reading into ``truth.csv`` (the IMU's biases and position into
``meta.json``'s truth).

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

import numpy as np
from mavsysid.flight.offline.controller import GeometricController, reference_samples
from mavsysid.flight.offline.effects import (
    TruthEffect,
    applies_wrench,
    config_truth_effects,
    effect_metadata,
    motor_time_constant,
)
from mavsysid.flight.offline.imu_sensor import ImuSensor
from mavsysid.flight.offline.sensor_noise import SensorNoise
from mavsysid.flight.offline.truth_step import advance_truth, summed_effect_wrench
from mavsysid.formats.flight_log import FlightRecorder
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.dynamics import ATT, POS, STATE_DIM
from mavsysid.vehicle.flatness import flat_to_state
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
        Add the config's motion-capture, rotor-speed and IMU noise (and IMU biases) to
        the log.
    seed : int
        Seed of the noise generator.
    imu : bool
        Record the IMU (gyro and accelerometer columns of ``pose.csv``).
    imu_position : tuple of 3 float or None
        The IMU's true offset from the centre of gravity, m, body FLU; None: the config's
        ``[imu] position``, else the centre of gravity.
    """

    physics_rate: float = 1000.0
    control_rate: float = 500.0
    log_rate: float = 100.0
    motor_lag: bool = True
    sensor_noise: bool = True
    seed: int = 0
    imu: bool = True
    imu_position: tuple[float, float, float] | None = None

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


_ZERO = np.zeros(3)


@dataclass
class _Truth:
    """The truth during one run: state, held commands and what one control tick needs."""

    y: np.ndarray
    n_cmd: np.ndarray
    dt: float
    tau: float
    args: tuple
    tick_effects: list[TruthEffect]
    step_effects: list[TruthEffect]
    #: The extra body force and torque of the effects in the last physics step (N, N·m).
    wrench: tuple[np.ndarray, np.ndarray] = (_ZERO, _ZERO)

    def advance(self, t: float, steps: int) -> None:
        """One control tick from time ``t``: ``steps`` physics steps under the effects.

        Wrenches of per-tick effects are evaluated once and held; per-step ones at each
        physics step. Without per-step effects the steps run in one compiled call.
        """
        held = _ZERO, _ZERO
        if self.tick_effects:
            held = summed_effect_wrench(self.tick_effects, t, self.y)
        self.wrench = held
        if not self.step_effects:
            advance_truth(self.y, self.n_cmd, self.dt, steps, self.tau, *self.args, *held)
            return
        for j in range(steps):
            force, torque = summed_effect_wrench(self.step_effects, t + j * self.dt, self.y)
            self.wrench = (force + held[0], torque + held[1])
            advance_truth(self.y, self.n_cmd, self.dt, 1, self.tau, *self.args, *self.wrench)


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
        self.imu: ImuSensor | None = None
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
        n_control = round(trajectory.duration * s.control_rate)
        # References are computed in blocks so that long flights need little memory.
        block = max(per_log, round(_REFERENCE_BLOCK_S * s.control_rate) // per_log * per_log)
        truth = self._start(trajectory)
        noise = SensorNoise(cfg, s.seed, enabled=s.sensor_noise)
        self.imu = ImuSensor(cfg, s.seed, s.sensor_noise, s.imu_position) if s.imu else None
        log = _LogBuffers(n_control // per_log + 1, cfg.rotor_count)
        recorder = None
        if directory is not None:
            recorder = FlightRecorder(directory, cfg, cfg.rotor_count, imu=s.imu)
            recorder.start(self._metadata(trajectory, description))
        self._warm_up(trajectory, truth)
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
                    log.store(row, t, truth.y, truth.n_cmd, ref[0:3])
                    if recorder is not None:
                        self._record(recorder, noise, row, t, truth, ref)
                    if progress is not None and row % int(s.log_rate) == 0:
                        progress(t, trajectory.duration)
                if i == n_control:
                    break
                saturated += self.controller.command(truth.y[:STATE_DIM], ref, truth.n_cmd)
                truth.advance(t, per_control)
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

    def _start(self, trajectory: Trajectory) -> _Truth:
        """The truth at rest at the trajectory's start; the effects bound and reset."""
        cfg = self.config
        dt = 1.0 / self.settings.physics_rate
        start = flat_to_state(trajectory.flat_outputs(np.array([0.0])), cfg, self.true_theta)
        y = np.concatenate([start.states()[0], start.rotor_speeds[0]])
        y[3:6] = 0.0
        effects = self.truth_effects
        truth = _Truth(
            y=y, n_cmd=start.rotor_speeds[0].copy(), dt=dt, tau=self._motor_time_constant(),
            args=(self.true_theta, float(cfg.mass), np.ascontiguousarray(cfg.rotor_positions),
                  np.ascontiguousarray(cfg.rotor_directions)),
            tick_effects=[e for e in effects if applies_wrench(e) and e.wrench_per_tick],
            step_effects=[e for e in effects if applies_wrench(e) and not e.wrench_per_tick],
        )
        for effect in effects:
            effect.bind(self.true_theta, cfg.rotor_positions, cfg.rotor_directions)
            effect.reset(dt)
        return truth

    def _warm_up(self, trajectory: Trajectory, truth: _Truth) -> None:
        """Load (or compile) the kernels before the clock starts, so wall_time is simulation."""
        self.controller.command(truth.y[:STATE_DIM].copy(), reference_samples(
            trajectory, np.zeros(1), self.config)[0], truth.n_cmd.copy())
        advance_truth(truth.y.copy(), truth.n_cmd, truth.dt, 0, truth.tau, *truth.args,
                      _ZERO, _ZERO)

    def _motor_time_constant(self) -> float:
        """The truth's motor lag, s: an effect's (a motor_lag) or the config's."""
        default = self.config.motor.time_constant if self.settings.motor_lag else 0.0
        return motor_time_constant(self.truth_effects, default)

    def _record(
        self, recorder: FlightRecorder, noise: SensorNoise, row: int, t: float, truth: _Truth,
        reference: np.ndarray,
    ) -> None:
        """Write what the sensors would report, and the truth, at log sample ``row``."""
        x = truth.y[:STATE_DIM]
        n = truth.y[STATE_DIM:]
        n_cmd = truth.n_cmd
        position, quaternion = x[POS].copy(), x[ATT].copy()
        logged_n = n.copy()
        for effect in self.truth_effects:
            position, quaternion = effect.measure_pose(t, position, quaternion)
            logged_n = effect.logged_rotor_speeds(t, logged_n, n_cmd)
        position, quaternion, logged_n = noise.apply(position, quaternion, logged_n)
        measured = true_imu = None
        if self.imu is not None:
            true_imu = self.imu.ideal(x, n, self.true_theta, *truth.wrench)
            measured = self.imu.measure(*true_imu, sample=row)
        recorder.record(t, position, quaternion, logged_n, reference, x, n, n_cmd,
                        imu=measured, true_imu=true_imu)

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
                **({"imu": self.imu.truth()} if self.imu is not None else {}),
                # Hidden from the model: what a diagnosis should find. Estimation reads
                # only truth.parameters, and only to report errors.
                "effects": [effect_metadata(e) for e in self.truth_effects if e.hidden],
            },
            "model_effects": [effect_metadata(e) for e in self.truth_effects if not e.hidden],
        }


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
