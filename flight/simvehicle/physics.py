"""Physics of the simulated vehicle: truth state, ground, motors, sensors and truth log.

One control tick (2 ms) runs the reference shaper (`mavsysid.flight.simvehicle.reference`),
the geometric controller on the config's nominal θ, and two 1 kHz RK4 steps of the truth
dynamics with motor lag (`mavsysid.flight.offline.truth_step.advance_truth`) on the true
θ. The ground is the plane at the start height: a landed vehicle rests on it (its state
frozen, the rotors idling when armed), a flying one that touches it is stopped there. The
published pose carries motion-capture-like noise
(`mavsysid.flight.offline.sensor_noise.SensorNoise`), drawn once per tick.
The truth log samples the true state at 200 Hz of sim time, between the two physics
steps of a tick when needed (control runs at 500 Hz, so 5 ms falls mid-tick).
The vehicle's IMU (`mavsysid.flight.offline.imu_sensor.ImuSensor`: the true gyro and
specific force with constant biases and white noise; on the ground the reaction to
gravity) is read once per tick for telemetry, and at the truth log's samples; its noise is
indexed by the sample's time in ms, so the two agree where they coincide.

Model effects (`mavsysid.flight.offline.effects`): the config's ``[effects]`` and any
hidden ones act on the truth as in the offline simulator — their wrench evaluated once
per flying tick at the session's sim time, a motor_lag's tau replacing the motor time
constant — and on what is published and logged (pose channel, commanded rotor speeds).
The ground plane of a ground effect is z = 0, which is the ground only for a start height
of 0.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.flight.offline.controller import REFERENCE_DIM, GeometricController
from mavsysid.flight.offline.effects import (
    TruthEffect,
    applies_wrench,
    config_truth_effects,
    motor_time_constant,
)
from mavsysid.flight.offline.imu_sensor import ImuSensor
from mavsysid.flight.offline.sensor_noise import SensorNoise
from mavsysid.flight.offline.truth_step import advance_truth, summed_effect_wrench
from mavsysid.flight.simvehicle.reference import (
    LIMITS_DIM,
    SHAPER_DIM,
    TARGET_DIM,
    hold_target,
    shape_step,
)
from mavsysid.formats.flight_log import FlightRecorder
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.dynamics import STATE_DIM
from mavsysid.vehicle.mav_model import rotor_speed_for_thrust
from mavsysid.vehicle.rotation import quat_yaw, rotate_inverse_tuple, rotate_tuple

__all__ = [
    "CONTROL_DT_US",
    "DEFAULT_LIMITS",
    "ORIGIN",
    "PHYSICS_STEPS",
    "TRUTH_PERIOD_US",
    "SimVehicle",
    "TruthLog",
]

#: Control tick, µs of sim time (500 Hz), and physics steps per tick (1 kHz).
CONTROL_DT_US = 2000
PHYSICS_STEPS = 2
#: Truth-log sample period, µs of sim time (200 Hz).
TRUTH_PERIOD_US = 5000
_PHYSICS_DT_US = CONTROL_DT_US // PHYSICS_STEPS

#: Latitude, longitude (deg) and altitude (m AMSL) of the world origin (0, 0, 0), which
#: is also the local NED origin of the telemetry: PX4 SITL's default place.
ORIGIN = (47.397742, 8.545594, 488.0)

#: Shaper limits before the autopilot applies its parameters: ArduPilot's defaults.
DEFAULT_LIMITS = (4.0, 8.0, 5.0, 2.5, 1.5, 2.5, 2.5, 2.0, 1.5)


class TruthLog:
    """Ground truth of a simulated session: ``truth.csv``, ``pose.csv`` and ``meta.json``.

    Parameters
    ----------
    directory : Path
        Where to write (created; must not already hold a pose log).
    config : VehicleConfig
    meta : dict
        Metadata (``simulated`` is set to True; the true parameters belong here).
    seed : int
        Seed of the noise on ``pose.csv`` (a draw of its own, with the published σ).
    noise : bool
        Add the sensor noise to ``pose.csv``.
    """

    def __init__(self, directory: Path, config: VehicleConfig, meta: dict[str, Any],
                 seed: int, noise: bool) -> None:
        self.recorder = FlightRecorder(directory, config, config.rotor_count, imu=True)
        self.recorder.start({**meta, "simulated": True})
        self._noise = SensorNoise(config, seed + 1, enabled=noise)
        self.closed = False

    def record(self, t: float, y: np.ndarray, n_cmd: np.ndarray, ref: np.ndarray,
               effects: Sequence[TruthEffect] = (),
               imu: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
               | None = None) -> None:
        """One row of each file at sim time ``t`` from the truth ``y = [x, n]``; ``effects``
        change what ``pose.csv`` reports (pose and rotor-speed hooks); ``imu`` is the IMU's
        (measured, true) reading, each (gyro, specific force), body FLU."""
        x, n = y[:STATE_DIM], y[STATE_DIM:]
        pos, quat, speeds = _sensed(effects, t, y, n_cmd)
        pos, quat, speeds = self._noise.apply(pos, quat, speeds)
        measured, true = imu if imu is not None else ((np.zeros(3), np.zeros(3)),) * 2
        self.recorder.record(t, pos, quat, speeds, ref, x, n, n_cmd, imu=measured,
                             true_imu=true)

    def finish(self, status: str, summary: dict[str, Any]) -> None:
        """Close the files and write the final metadata (once)."""
        if not self.closed:
            self.closed = True
            self.recorder.finish(status, summary)


def _sensed(effects: Sequence[TruthEffect], t: float, y: np.ndarray, n_cmd: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the sensors report before noise: the effects' pose and rotor-speed hooks."""
    position, quaternion = y[0:3].copy(), y[6:10].copy()
    speeds = y[STATE_DIM:].copy()
    for effect in effects:
        position, quaternion = effect.measure_pose(t, position, quaternion)
        speeds = effect.logged_rotor_speeds(t, speeds, n_cmd)
    return position, quaternion, speeds


class SimVehicle:
    """The simulated multirotor: truth dynamics, ground contact and sensors.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle; the controller uses its nominal θ.
    true_theta : ndarray, shape (6,)
        The truth's θ.
    start : sequence of 3 float
        Start position on the ground, m, world ENU; the ground is at its height.
    yaw : float
        Start heading, rad (ENU).
    seed : int
        Seed of the published pose's noise.
    sensor_noise : bool
        Add motion-capture and rotor-speed noise to what is published.
    truth_log : TruthLog, optional
    effects : sequence of TruthEffect
        Hidden truth-side effects (`mavsysid.flight.offline.effects.hidden_effect`); the
        config's own ``effects`` are simulated too, before these.
    imu : ImuSensor, optional
        The vehicle's IMU; by default one at the config's ``[imu] position`` with biases
        and noise from ``seed`` (none without ``sensor_noise``).
    """

    def __init__(self, config: VehicleConfig, true_theta: np.ndarray, start=(0.0, 0.0, 0.0),
                 yaw: float = 0.0, seed: int = 0, sensor_noise: bool = True,
                 truth_log: TruthLog | None = None,
                 effects: Sequence[TruthEffect] = (), imu: ImuSensor | None = None) -> None:
        k = config.rotor_count
        self.config = config
        self.true_theta = np.asarray(true_theta, dtype=float).reshape(6)
        self.controller = GeometricController(config)
        self.ground_z = float(start[2])
        self.y = np.zeros(STATE_DIM + k)
        self.y[0:3] = start
        self.y[6], self.y[9] = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
        self.n_cmd = np.zeros(k)
        # Each motor's speed per commanded speed: 1, or less for a weak motor (`weaken`).
        self.motor_gains = np.ones(k)
        self._n_applied = np.zeros(k)
        self.ref = np.zeros(REFERENCE_DIM)
        self.target = np.zeros(TARGET_DIM)
        self.shaper = np.zeros(SHAPER_DIM)
        self.limits = np.array(DEFAULT_LIMITS, dtype=float)
        assert self.limits.size == LIMITS_DIM
        self.landed = True
        self.ground_contact = 0.0  # s of uninterrupted contact while flying
        self.tick = 0
        self.truth_log = truth_log
        self.effects: list[TruthEffect] = [*config_truth_effects(config), *effects]
        for effect in self.effects:
            effect.bind(self.true_theta, config.rotor_positions)
            effect.reset(_PHYSICS_DT_US * 1e-6)
        self._tick_effects = [e for e in self.effects if applies_wrench(e)]
        # A delayed pose interpolates a history: feed it every tick, not only when asked.
        self._pose_history = any(e.name == "pose_delay" for e in self.effects)
        # The truth log keeps its own copies: a delay's pose history is per consumer.
        self._log_effects = copy.deepcopy(self.effects)
        self._tau = motor_time_constant(self.effects, config.motor.time_constant)
        self._wrench = (np.zeros(3), np.zeros(3))
        self._args = (self.true_theta, float(config.mass),
                      np.ascontiguousarray(config.rotor_positions),
                      np.ascontiguousarray(config.rotor_directions))
        self._zero = np.zeros(3)
        self._noise = SensorNoise(config, seed, enabled=sensor_noise)
        self._measured: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._measured_tick = -1
        self.imu = imu if imu is not None else ImuSensor(config, seed, sensor_noise)
        self._imu_reading: tuple[np.ndarray, np.ndarray] | None = None
        self._imu_tick = -1
        self.idle_speed = self._idle_speed(config)
        self.hold_here()
        self._reset_shaper()
        self._warm_up()

    @staticmethod
    def _idle_speed(config: VehicleConfig) -> float:
        """Rotor speed when armed on the ground (like MOT_SPIN_ARM): 20 % of the maximum,
        or less, so that idling lifts under a third of the weight."""
        limit = float(rotor_speed_for_thrust(config.parameters.c_T,
                                             config.hover_thrust / 3.0 / config.rotor_count))
        lim = config.limits
        return max(lim.rotor_speed_min, min(0.2 * lim.rotor_speed_max, limit))

    def _warm_up(self) -> None:
        """Load the compiled kernels now rather than in the first flying tick."""
        y, ref, n = self.y.copy(), self.ref.copy(), self.n_cmd.copy()
        shape_step(self.target.copy(), self.shaper.copy(), self.limits, 0.002, ref)
        self.controller.command(y[:STATE_DIM], ref, n)
        advance_truth(y, n, 0.001, 1, self._tau, *self._args, self._zero, self._zero)

    # --- state -------------------------------------------------------------------------
    @property
    def time_us(self) -> int:
        """Sim time of the current tick, µs."""
        return self.tick * CONTROL_DT_US

    @property
    def position(self) -> np.ndarray:
        """True position, m, world ENU (a view)."""
        return self.y[0:3]

    @property
    def quaternion(self) -> np.ndarray:
        """True attitude [w, x, y, z], body FLU → world ENU (a view)."""
        return self.y[6:10]

    @property
    def body_rates(self) -> np.ndarray:
        """True body rates, rad/s, FLU (a view)."""
        return self.y[10:13]

    @property
    def rotor_speeds(self) -> np.ndarray:
        """True (lagged) rotor speeds, rad/s (a view)."""
        return self.y[STATE_DIM:]

    def velocity(self) -> np.ndarray:
        """True velocity, m/s, world ENU."""
        return np.array(rotate_tuple(self.y[6:10], self.y[3:6]))

    def yaw(self) -> float:
        """True heading, rad, ENU."""
        return float(quat_yaw(self.y[6:10]))

    def tilt(self) -> float:
        """Angle between the body z axis and the vertical, rad."""
        x, y = float(self.y[7]), float(self.y[8])
        return math.acos(min(1.0, max(-1.0, 1.0 - 2.0 * (x * x + y * y))))

    def height(self) -> float:
        """Height above the ground, m."""
        return float(self.y[2]) - self.ground_z

    def measured(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Published (noisy) position ENU, attitude and rotor speeds at this tick."""
        if self._measured_tick != self.tick:
            sensed = _sensed(self.effects, self.time_us * 1e-6, self.y, self.n_cmd)
            self._measured = self._noise.apply(*sensed, sample=self.tick)
            self._measured_tick = self.tick
        assert self._measured is not None
        return self._measured

    def _imu_at(self, t_us: int) -> tuple[tuple[np.ndarray, np.ndarray],
                                          tuple[np.ndarray, np.ndarray]]:
        """The IMU's (measured, true) reading of the state now, sampled at ``t_us``."""
        true = self.imu.ideal(self.y[:STATE_DIM], self.y[STATE_DIM:], self.true_theta,
                              *self._wrench, landed=self.landed)
        return self.imu.measure(*true, sample=t_us // 1000), true

    def imu_measured(self) -> tuple[np.ndarray, np.ndarray]:
        """The IMU's gyro (rad/s) and specific force (m/s²) at this tick, body FLU."""
        if self._imu_tick != self.tick:
            self._imu_reading = self._imu_at(self.time_us)[0]
            self._imu_tick = self.tick
        assert self._imu_reading is not None
        return self._imu_reading

    # --- transitions -------------------------------------------------------------------
    def weaken(self, rotor: int, thrust_factor: float) -> None:
        """Make ``rotor``'s motor weak: at any command it turns at √F of the commanded
        speed, so its thrust (and drag and moment) is F times what the command asks; the
        controller's outputs show it working harder (as ArduPilot SITL's SIM_ENGINE_MUL).

        Parameters
        ----------
        rotor : int
            Config rotor index, 0-based.
        thrust_factor : float
            F in (0, 1].
        """
        self.motor_gains[rotor] = math.sqrt(thrust_factor)

    def hold_here(self) -> None:
        """Make the target the current position and heading."""
        hold_target(self.target, self.y[0:3], self.yaw())

    def _reset_shaper(self) -> None:
        self.shaper[0:3] = self.y[0:3]
        self.shaper[3:6] = self.velocity()
        self.shaper[6] = self.yaw()

    def lift_off(self) -> None:
        """Leave the ground: the shaper starts from rest where the vehicle stands."""
        if self.landed:
            self.landed = False
            self.ground_contact = 0.0
            self._reset_shaper()

    def settle(self) -> None:
        """Come to rest on the ground, level, keeping the heading."""
        yaw = self.yaw()
        self.y[2] = self.ground_z
        self.y[3:6] = 0.0
        self.y[6:10] = (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))
        self.y[10:13] = 0.0
        self.landed = True
        self.ground_contact = 0.0
        self.hold_here()
        self._reset_shaper()

    # --- one tick ----------------------------------------------------------------------
    def step(self, armed: bool) -> None:
        """Advance the truth by one control tick (2 ms); ``armed``: motors may spin."""
        dt = CONTROL_DT_US * 1e-6
        t_us = self.time_us
        if self.landed:
            self.n_cmd[:] = self.idle_speed if armed else 0.0
            self.ref[:] = 0.0
            self.ref[0:3] = self.y[0:3]
            self.ref[9] = self.yaw()
        else:
            shape_step(self.target, self.shaper, self.limits, dt, self.ref)
            if armed:
                self.controller.command(self.y[:STATE_DIM], self.ref, self.n_cmd)
            else:
                self.n_cmd[:] = 0.0
        np.multiply(self.n_cmd, self.motor_gains, out=self._n_applied)
        if self._tick_effects and not self.landed:
            self._wrench = summed_effect_wrench(self._tick_effects, t_us * 1e-6, self.y)
        record = self.truth_log is not None
        sub = -1
        if record:
            for s in range(PHYSICS_STEPS):
                if (t_us + s * _PHYSICS_DT_US) % TRUTH_PERIOD_US == 0:
                    sub = s
        if self.landed:
            if sub >= 0:
                self._record(t_us + sub * _PHYSICS_DT_US)
            self._spin_on_ground(dt)
        elif sub < 0:
            self._physics(PHYSICS_STEPS)
        else:
            self._physics(sub)
            self._record(t_us + sub * _PHYSICS_DT_US)
            self._physics(PHYSICS_STEPS - sub)
        self.tick += 1
        if self._pose_history:
            self.measured()

    def _physics(self, steps: int) -> None:
        if steps <= 0:
            return
        advance_truth(self.y, self._n_applied, _PHYSICS_DT_US * 1e-6, steps, self._tau,
                      *self._args, *self._wrench)
        if self.y[2] <= self.ground_z:
            # Ground contact: no sinking in; a downward world velocity is stopped.
            self.y[2] = self.ground_z
            vx, vy, vz = rotate_tuple(self.y[6:10], self.y[3:6])
            if vz < 0.0:
                self.y[3:6] = rotate_inverse_tuple(self.y[6:10], (vx, vy, 0.0))
            self.ground_contact += steps * _PHYSICS_DT_US * 1e-6
        else:
            self.ground_contact = 0.0

    def _spin_on_ground(self, dt: float) -> None:
        n = self.y[STATE_DIM:]
        if self._tau > 0.0:
            n += (self._n_applied - n) * (1.0 - math.exp(-dt / self._tau))
        else:
            n[:] = self._n_applied

    def _record(self, t_us: int) -> None:
        assert self.truth_log is not None
        self.truth_log.record(t_us * 1e-6, self.y, self.n_cmd, self.ref, self._log_effects,
                              self._imu_at(t_us))
