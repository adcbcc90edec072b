"""The vehicle configuration's data types: what a vehicle TOML file holds, as frozen dataclasses.

Loading and validation are in `mavsysid.vehicle.config` (the public entry point, which
re-exports these types), `mavsysid.vehicle.config_schema` and
`mavsysid.vehicle.config_checks`; writing is in `mavsysid.vehicle.config_toml`.

A configuration holds what is known about a vehicle before a flight: its mass and
rotor geometry (taken as known), the nominal (prior) physical parameters
θ = [c_T, c_D, c_M, j_x, j_y, j_z], its limits, its motors, its noise, and the model
effects beyond the paper's model that are known to act on it (``[effects.NAME]`` tables,
`mavsysid.vehicle.model_effects`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.effect_base import ModelEffect
from mavsysid.vehicle.parameters import (
    PAPER_THETA,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    EstimatedQuantity,
)

__all__ = [
    "ACCEL_BIAS_SIGMA",
    "ACCEL_SIGMA",
    "ALLOCATION_MODES",
    "ANGULAR_NOISE_DENSITY",
    "CURVE_SIGMA",
    "GYRO_BIAS_SIGMA",
    "GYRO_SIGMA",
    "LINEAR_NOISE_DENSITY",
    "PARAMETER_NAMES",
    "PARAMETER_UNITS",
    "Limits",
    "MotorConfig",
    "NoiseConfig",
    "Parameters",
    "RotorConfig",
    "VehicleConfig",
    "default_noise_densities",
]


#: ``[limits] allocation``: how rotor limits bound the wrench. "pseudo_inverse": n² = A⁺ w
#: must lie in the rotor box (the mixers of ArduPilot, PX4 and RotorS's Lee controller);
#: "exact": any n² in the box with A n² = w (a controller that allocates over the null
#: space), `mavsysid.vehicle.allocation_polytope`. mavsysid's simulated controllers mix
#: as this says (`mavsysid.flight.offline.null_space_mixer`).
ALLOCATION_MODES: tuple[str, ...] = ("pseudo_inverse", "exact")

#: Default unmodelled linear acceleration noise density, m/s²·√s.
LINEAR_NOISE_DENSITY = 0.02
#: Default unmodelled angular acceleration noise density, rad/s²·√s.
ANGULAR_NOISE_DENSITY = 0.02

# IMU noise defaults, typical of the real PX4 logs of ../shared/real-logs (a Pixhawk
# AUAV-X2.1, a Pixhawk 4 Pro, a Cube Orange, PX4 SITL; bench/imu_noise_real_logs.py): the
# white noise of a logged sample, the σ of the samples minus their 15 Hz low-pass, is
# 0.0005–0.005 rad/s (gyro) and 0.007–0.036 m/s² (accelerometer) in four of them, at rest
# and in flight, up to 0.046 rad/s and 0.086 m/s² in the fifth; a constant bias shows at
# rest as a mean gyro of 0–0.007 rad/s per axis and a |specific force| up to 0.19 m/s²
# off g (docs/architecture.md, "Noise defaults").
#: Gyro white noise σ per logged sample, rad/s.
GYRO_SIGMA = 0.005
#: Accelerometer white noise σ per logged sample, m/s².
ACCEL_SIGMA = 0.04
#: σ of a gyro's constant bias per axis, rad/s.
GYRO_BIAS_SIGMA = 0.005
#: σ of an accelerometer's constant bias per axis, m/s².
ACCEL_BIAS_SIGMA = 0.1

#: Relative 1σ of a motor curve's rotor speeds: a datasheet's top speed against the one
#: under load (KV and propeller spread, the ESC's timing) is good to a few per cent.
CURVE_SIGMA = 0.05


@dataclass(frozen=True)
class RotorConfig:
    """One rotor.

    Attributes
    ----------
    position : tuple of 3 float
        Rotor hub position relative to the centre of gravity, m, body FLU frame.
    direction : int
        +1 spins counter-clockwise seen from above (reaction torque -c_M n² about
        z_B), -1 clockwise. The paper's ε_i.
    """

    position: tuple[float, float, float]
    direction: int


@dataclass(frozen=True)
class Parameters:
    """The identified parameters θ, in SI units.

    Attributes
    ----------
    c_T : float
        Thrust coefficient, N/(rad/s)²: rotor thrust c_T n².
    c_D : float
        Rotor drag coefficient, s/m: rotor drag -c_T n² diag(c_D, c_D, 0)(v_B + ω × r_i).
    c_M : float
        Moment coefficient, N·m/(rad/s)² (absolute, not RotorS's ratio c_M/c_T).
    J : tuple of 3 float
        Principal moments of inertia [j_x, j_y, j_z], kg·m².
    """

    c_T: float
    c_D: float
    c_M: float
    J: tuple[float, float, float]

    def as_array(self) -> np.ndarray:
        """θ as a float array of shape (6,), in the order of `PARAMETER_NAMES`."""
        return np.array([self.c_T, self.c_D, self.c_M, *self.J], dtype=float)

    @classmethod
    def from_array(cls, theta: np.ndarray) -> Parameters:
        """Build from θ of shape (6,) in the order of `PARAMETER_NAMES`.

        Parameters
        ----------
        theta : ndarray, shape (6,)
            [c_T, c_D, c_M, j_x, j_y, j_z], SI.
        """
        t = [float(v) for v in np.asarray(theta, dtype=float).reshape(6)]
        return cls(c_T=t[0], c_D=t[1], c_M=t[2], J=(t[3], t[4], t[5]))


@dataclass(frozen=True)
class Limits:
    """Actuator and planner limits (optional `[limits]` keys have these defaults).

    Attributes
    ----------
    rotor_speed_max, rotor_speed_min : float
        Rotor speed range, rad/s.
    thrust_min_ratio, thrust_max_ratio : float
        Collective thrust range, × m g.
    body_rate_max : float
        Largest body-rate norm, rad/s.
    yaw_acceleration_max : float
        Largest yaw acceleration, rad/s².
    speed_max : float
        Largest speed, m/s.
    segment_time_max : float
        Longest planned segment, s.
    """

    rotor_speed_max: float
    rotor_speed_min: float = 0.0
    thrust_min_ratio: float = 0.5
    thrust_max_ratio: float = 1.8
    body_rate_max: float = 3.0
    yaw_acceleration_max: float = 2.0 * math.pi
    speed_max: float = 3.0
    segment_time_max: float = 3.0


@dataclass(frozen=True)
class MotorConfig:
    """Motor lag (simulator truth side) and the motor curve (logs without rotor speeds).

    Attributes
    ----------
    time_constant : float
        First-order lag between commanded and actual rotor speed, s.
    pwm_min, pwm_max : float
        Motor output PWM for zero and full throttle u, µs.
    thrust_expo : float
        ArduPilot's MOT_THST_EXPO e in [0, 1]: thrust ∝ (1 − e) u + e u², so a rotor
        speed is rotor_speed_max · sqrt((1 − e) u + e u²).
    voltage : float
        Battery voltage at which that curve holds, V; commanded rotor speeds then scale
        with the logged battery voltage (`mavsysid.formats.motor_curve`). 0: not stated,
        not scaled.
    curve_sigma : float
        Relative 1σ of the curve's rotor speeds (of ``rotor_speed_max``): how well the
        curve is known. c_T and c_M from commanded rotor speeds carry twice it. The
        default, 5 %, is a curve from a motor's datasheet; a thrust-stand fit states its
        own; 0 is a curve exact by construction (a simulator's).
    """

    time_constant: float = 0.02
    pwm_min: float = 1000.0
    pwm_max: float = 2000.0
    thrust_expo: float = 0.65
    voltage: float = 0.0
    curve_sigma: float = CURVE_SIGMA


@dataclass(frozen=True)
class NoiseConfig:
    """Sensor noise (σ) and process-noise densities.

    Attributes
    ----------
    position_sigma : float
        Motion-capture position noise σ, m.
    attitude_sigma : float
        Motion-capture attitude noise σ, rad (per axis of the body-frame error).
    rotor_speed_sigma : float
        Noise σ on logged rotor speeds, rad/s.
    force_density : float
        White-noise density of the unmodelled body force, N·√s (continuous time).
    moment_density : float
        White-noise density of the unmodelled body moment, N·m·√s.
    gyro_sigma : float
        IMU gyro white noise σ of each logged sample, rad/s, per axis.
    accel_sigma : float
        IMU accelerometer white noise σ of each logged sample, m/s², per axis.
    gyro_bias_sigma : float
        σ of the gyro's constant bias, rad/s, per axis (what remains after the
        autopilot's calibration).
    accel_bias_sigma : float
        σ of the accelerometer's constant bias, m/s², per axis.
    """

    position_sigma: float = 0.0005
    attitude_sigma: float = math.radians(0.1)
    rotor_speed_sigma: float = 0.0
    force_density: float = 0.0
    moment_density: float = 0.0
    gyro_sigma: float = GYRO_SIGMA
    accel_sigma: float = ACCEL_SIGMA
    gyro_bias_sigma: float = GYRO_BIAS_SIGMA
    accel_bias_sigma: float = ACCEL_BIAS_SIGMA


@dataclass(frozen=True)
class VehicleConfig:
    """A complete vehicle description.

    Attributes
    ----------
    name : str
        Short name (the shipped name, or the file stem).
    mass : float
        Mass, kg (weighed, not estimated).
    rotors : tuple of RotorConfig
        The rotors, in the order of the rotor-speed columns n1..nk of a pose log.
    parameters : Parameters
        Nominal (prior) values of θ.
    limits, motor, noise
        See the respective classes.
    effects : tuple of ModelEffect
        Known model effects (``[effects.NAME]``), part of the model everywhere: the
        simulators' physics and the estimator's model. Empty by default.
    source : str
        Where the configuration came from (a path, or ``builtin:NAME``).
    autopilot_frame : str or None
        ``[autopilot] frame``: the autopilot frame whose motor outputs the rotors are
        (a name of `mavsysid.vehicle.motor_order.FRAME_NAMES`); the readers put a log's
        motor outputs into the config's rotor order through it. None: log output i is
        rotor i.
    box : tuple of 6 float or None
        ``[flight] box``: the flight box [x_min, y_min, z_min, x_max, y_max, z_max], m,
        world ENU, where this vehicle may be flown (``mavsysid stream`` uses it when no
        ``--box`` is given). None: not set.
    allocation : str
        ``[limits] allocation``, one of `ALLOCATION_MODES`: how the rotor limits bound
        the wrench a plan may ask for. The default, "pseudo_inverse", is what the
        controllers that fly a plan realise (autopilot mixers, mavsysid's simulators);
        "exact" only for a vehicle whose controller allocates over the null space. Kept
        out of `Limits`, whose fields are numbers (the trajectory file copies them).
    imu_position : tuple of 3 float or None
        ``[imu] position``: the IMU's offset from the centre of gravity, m, body FLU (the
        lever arm between the accelerometer and the CoG). None: not stated.
    extra_quantities : tuple of EstimatedQuantity
        Nuisance quantities estimated beside θ, each with its prior and the term by which
        it enters the model (`mavsysid.vehicle.parameters`); the estimator adds those a
        log calls for. Not part of the vehicle file. Empty by default: the paper's θ.
    """

    name: str
    mass: float
    rotors: tuple[RotorConfig, ...]
    parameters: Parameters
    limits: Limits
    motor: MotorConfig = field(default_factory=MotorConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    source: str = ""
    effects: tuple[ModelEffect, ...] = ()
    autopilot_frame: str | None = None
    box: tuple[float, ...] | None = None
    allocation: str = "pseudo_inverse"
    imu_position: tuple[float, float, float] | None = None
    extra_quantities: tuple[EstimatedQuantity, ...] = ()

    @property
    def rotor_count(self) -> int:
        """Number of rotors k."""
        return len(self.rotors)

    @property
    def rotor_positions(self) -> np.ndarray:
        """Rotor positions, shape (k, 3), m, body FLU."""
        return np.array([r.position for r in self.rotors], dtype=float)

    @property
    def rotor_directions(self) -> np.ndarray:
        """Rotor spin directions ε_i, shape (k,), float ±1."""
        return np.array([r.direction for r in self.rotors], dtype=float)

    @property
    def quantities(self) -> tuple[EstimatedQuantity, ...]:
        """The estimated quantities: the paper's θ, then ``extra_quantities``."""
        return PAPER_THETA + self.extra_quantities

    @property
    def theta(self) -> np.ndarray:
        """Nominal θ, shape (6,)."""
        return self.parameters.as_array()

    @property
    def hover_thrust(self) -> float:
        """Collective thrust in hover m g, N."""
        return self.mass * GRAVITY

    def with_parameters(self, parameters: Parameters | np.ndarray) -> VehicleConfig:
        """A copy with other nominal parameters (a `Parameters` or θ of shape (6,)).

        Parameters
        ----------
        parameters : Parameters or ndarray, shape (6,)
            The new nominal θ, SI.
        """
        if not isinstance(parameters, Parameters):
            parameters = Parameters.from_array(parameters)
        return replace(self, parameters=parameters)


def default_noise_densities(
    mass: float, inertia: tuple[float, float, float]
) -> tuple[float, float]:
    """Process-noise densities used when `[noise]` does not give them.

    Stated as unmodelled accelerations so that one default suits a 30 g quad and a 3 kg
    hexacopter alike: 0.02 m/s²·√s of linear and 0.02 rad/s²·√s of angular acceleration
    noise. Estimation can fit the level to a flight (`mavsysid.estimation.filter.likelihood`).

    Parameters
    ----------
    mass : float
        Vehicle mass, kg.
    inertia : tuple of 3 float
        Principal moments of inertia, kg·m².

    Returns
    -------
    force_density : float
        ``0.02 m``, N·√s.
    moment_density : float
        ``0.02 mean(J)``, N·m·√s.
    """
    return LINEAR_NOISE_DENSITY * mass, ANGULAR_NOISE_DENSITY * float(np.mean(inertia))
