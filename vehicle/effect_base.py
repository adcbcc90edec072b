"""The base of the model effects: the effect class, its inputs, and the shared wrench helpers.

An effect (`ModelEffect`) enters the model through up to three channels (see
`mavsysid.vehicle.model_effects`, which holds the catalogue of named effects):
``wrench`` (extra body force and torque, on arrays of N samples, `EffectInputs`),
``pose`` (what the motion-capture system reports) and ``rotor_speeds`` (the speeds
acting on the body).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from mavsysid.vehicle.mav_model import rotor_thrust, rotor_wrench
from mavsysid.vehicle.rotation import quat_to_matrix

from mavsysid.errors import InputError

__all__ = [
    "EffectInputs",
    "EffectParameter",
    "ModelEffect",
    "cross3",
    "hub_forces_wrench",
    "rotor_force_wrench",
    "time_derivative",
    "total_wrench",
    "zero_wrench",
]


@dataclass(frozen=True)
class EffectParameter:
    """One parameter of an effect.

    Attributes
    ----------
    name : str
        Identifier used in configs, the CLI and JSON.
    unit : str
    description : str
    scale : float
        A typical magnitude (same unit): the step of searches and the unit of scaled fits.
    sign : {"positive", "nonnegative"} or None
        The sign the parameter has by its meaning (a time constant, a drag); None: any.
        Vehicle files are checked against it and the fits kept to it.
    """

    name: str
    unit: str
    description: str
    scale: float
    sign: str | None = None


@dataclass(frozen=True)
class EffectInputs:
    """Samples at which effects are evaluated (N of them); every array is float.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time since the start of the flight, s.
    position : ndarray, shape (N, 3)
        Body-frame origin, world ENU, m.
    quaternion : ndarray, shape (N, 4)
        Attitude [w, x, y, z], body → world.
    velocity : ndarray, shape (N, 3)
        Velocity over ground in the body frame v_B, m/s.
    rates : ndarray, shape (N, 3)
        Body rates ω, rad/s.
    rotor_speeds : ndarray, shape (N, k)
        Speeds acting on the body, rad/s.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI.
    rotor_positions : ndarray, shape (k, 3)
        Rotor hubs in the body frame, m.
    rotor_directions : ndarray, shape (k,), optional
        Spin directions ε_i (+1 counter-clockwise seen from above); an effect that needs
        them (rotor inertia) adds nothing without them.
    rotor_speed_rates : ndarray, shape (N, k), optional
        ṅ, rad/s²; without it `rotor_accelerations` differentiates ``rotor_speeds``.
    angular_acceleration : ndarray, shape (N, 3), optional
        ω̇, rad/s², body frame, where the caller has it (what an IMU off the centre of
        gravity feels, `mavsysid.vehicle.imu`).
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    rates: np.ndarray
    rotor_speeds: np.ndarray
    theta: np.ndarray
    rotor_positions: np.ndarray
    rotor_directions: np.ndarray | None = None
    rotor_speed_rates: np.ndarray | None = None
    angular_acceleration: np.ndarray | None = None

    def rotation(self) -> np.ndarray:
        """R(q) body → world, shape (N, 3, 3)."""
        return quat_to_matrix(self.quaternion)

    def hub_velocities(self) -> np.ndarray:
        """v_B + ω × r_i of every rotor hub, shape (N, k, 3), m/s."""
        return self.velocity[:, None, :] + cross3(self.rates[:, None, :],
                                                    self.rotor_positions[None, :, :])

    def rotor_accelerations(self) -> np.ndarray:
        """ṅ of every rotor, shape (N, k), rad/s²: given, or `time_derivative` of the speeds."""
        if self.rotor_speed_rates is not None:
            return self.rotor_speed_rates
        return time_derivative(self.t, self.rotor_speeds)

    def rotor_thrusts(self) -> np.ndarray:
        """c_T n_i², shape (N, k), N."""
        return rotor_thrust(self.theta[0], self.rotor_speeds)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (size 3), broadcasting; shape of the broadcast.

    np.cross's axis handling costs tens of µs a call, which dominates the simulator's
    per-tick evaluation of one sample; this is the same formula without it.

    Parameters
    ----------
    a, b : ndarray, shape (..., 3)
        The factors.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def time_derivative(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """dx/dt along axis 0 by central differences (one-sided at the ends), shape of x.

    Times that do not increase (a repeated row) would divide by zero: the samples are then
    taken as evenly spaced at the median step. Fewer than two samples give zeros.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times, s.
    x : ndarray, shape (N, ...)
        Samples to differentiate along axis 0.
    """
    x = np.asarray(x, dtype=float)
    if len(t) < 2:
        return np.zeros_like(x)
    dt = np.diff(t)
    if np.all(dt > 0.0):
        return np.gradient(x, t, axis=0)
    step = float(np.median(dt))
    return np.gradient(x, step if step > 0.0 else 1.0, axis=0)


def zero_wrench(inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
    """No force and no torque: two zero arrays of shape (N, 3).

    Parameters
    ----------
    inputs : EffectInputs
        State, rotor speeds and vehicle at N samples.
    """
    n = len(inputs.t)
    return np.zeros((n, 3)), np.zeros((n, 3))


def hub_forces_wrench(inputs: EffectInputs, forces: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Sum of per-rotor body forces (N, k, 3) acting at the hubs: force and torque (N, 3).

    Parameters
    ----------
    inputs : EffectInputs
        State, rotor speeds and vehicle at N samples.
    forces : ndarray, shape (N, k, 3)
        Body force at each rotor hub, N.
    """
    torque = cross3(inputs.rotor_positions[None, :, :], forces).sum(axis=1)
    return forces.sum(axis=1), torque


def rotor_force_wrench(inputs: EffectInputs, rotor_positions: np.ndarray | None = None,
                       velocity: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Wrench of the paper's rotor forces F_i alone (thrust and rotor drag, paper Eq. drag).

    The rotors' reaction moments −ε_i c_M n_i² are left out (c_M = 0): they depend
    neither on where the rotors sit nor on the airspeed, so the effects that move the
    arms or the air cancel them anyway, and `EffectInputs` carries no spin directions.

    Parameters
    ----------
    inputs : EffectInputs
    rotor_positions : ndarray, shape (k, 3), optional
        Arms to use instead of ``inputs.rotor_positions``, m.
    velocity : ndarray, shape (N, 3), optional
        Body velocity (airspeed) to use instead of ``inputs.velocity``, m/s.

    Returns
    -------
    force, torque : ndarray, shape (N, 3)
        Σ F_i (N) and Σ r_i × F_i (N·m), evaluated by `mavsysid.vehicle.mav_model`.
    """
    theta = np.array(inputs.theta, dtype=float)
    theta[2] = 0.0
    r = inputs.rotor_positions if rotor_positions is None else rotor_positions
    v = inputs.velocity if velocity is None else velocity
    return rotor_wrench(inputs.rotor_speeds, theta, r, np.zeros(r.shape[0]), v, inputs.rates)


class ModelEffect:
    """Base class: an effect with its parameter values; every channel defaults to none.

    Parameters
    ----------
    **values : float
        The effect's parameters by name, SI (an absent one is 0).
    """

    name: ClassVar[str] = "effect"
    title: ClassVar[str] = ""
    description: ClassVar[str] = ""
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    #: Channels through which the effect enters: a subset of {"wrench", "pose",
    #: "rotor_speeds"}.
    channels: ClassVar[frozenset[str]] = frozenset()
    #: Whether the wrench acts on the velocity through the air: with a wind in the model
    #: (`air_velocity`), `total_wrench` evaluates it at the airspeed.
    airspeed: ClassVar[bool] = False
    #: The diagnosis fits a one-parameter effect whose channel is not linear in it by a
    #: profile search over ``numpy.arange(*profile)`` (start, stop, step; SI, a physically
    #: plausible range); None: by regression columns.
    profile: ClassVar[tuple[float, float, float] | None] = None

    def __init__(self, **values: float) -> None:
        known = {p.name for p in self.parameters}
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(f"effect {self.name}: unknown parameter {unknown[0]!r}; "
                             f"expected one of {', '.join(sorted(known))}")
        for key, value in values.items():
            if not np.isfinite(value):
                raise InputError(f"effect {self.name}: parameter {key} = {value}: "
                                 "expected a finite number")
        self.values = np.array([float(values.get(p.name, 0.0)) for p in self.parameters])

    @classmethod
    def parameter_names(cls) -> tuple[str, ...]:
        return tuple(p.name for p in cls.parameters)

    @classmethod
    def parameter_scales(cls) -> np.ndarray:
        return np.array([p.scale for p in cls.parameters])

    def as_dict(self) -> dict[str, float]:
        """Parameter values by name (SI)."""
        return {p.name: float(v) for p, v in zip(self.parameters, self.values, strict=True)}

    def with_values(self, values: np.ndarray) -> ModelEffect:
        """The same effect with other parameter values, shape (P,).

        Parameters
        ----------
        values : ndarray, shape (P,)
            Parameter values in the order of ``parameters``, SI.
        """
        return type(self)(**dict(zip(self.parameter_names(), map(float, values), strict=True)))

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v:g}" for k, v in self.as_dict().items())
        return f"{type(self).__name__}({inner})"

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and np.array_equal(self.values, other.values)  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash((self.name, tuple(self.values)))

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        """Extra body force (N) and torque (N·m), each of shape (N, 3).

        Parameters
        ----------
        inputs : EffectInputs
            State, rotor speeds and vehicle at N samples.
        """
        return zero_wrench(inputs)

    def air_velocity(self, inputs: EffectInputs) -> np.ndarray | None:
        """The body's velocity through the air v_B − Rᵀ w (N, 3), m/s; None: still air.

        Parameters
        ----------
        inputs : EffectInputs
            State, rotor speeds and vehicle at N samples.
        """
        return None

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Truth → measurement: the pose reported at times t given the true pose at t.

        Shapes (N,), (N, 3), (N, 4). A delay needs the pose history, so it is applied
        by interpolating over the whole arrays (the simulator keeps a history).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times, s.
        position : ndarray, shape (N, 3)
            True positions, m.
        quaternion : ndarray, shape (N, 4)
            True attitudes [w, x, y, z].
        """
        return position, quaternion

    def corrected_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Measurement → model: times, positions and attitudes of the model's body frame.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times, s.
        position : ndarray, shape (N, 3)
            Measured positions, m.
        quaternion : ndarray, shape (N, 4)
            Measured attitudes [w, x, y, z].
        """
        return t, position, quaternion

    def acting_rotor_speeds(self, t: np.ndarray, logged: np.ndarray) -> np.ndarray:
        """Speeds acting on the body given the logged ones, shape (N, k), rad/s.

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times, s.
        logged : ndarray, shape (N, k)
            Logged rotor speeds, rad/s.
        """
        return logged


def total_wrench(effects: tuple[ModelEffect, ...] | list[ModelEffect], inputs: EffectInputs
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Sum of the wrenches of ``effects`` at ``inputs``: force and torque (N, 3) each.

    An effect that moves the air (a wind: `ModelEffect.air_velocity`) changes what every
    airspeed effect (`ModelEffect.airspeed`: body drag, linear rotor drag) sees: those are
    evaluated at the airspeed, so each is written once for still air.

    Parameters
    ----------
    effects : sequence of ModelEffect
        The effects.
    inputs : EffectInputs
        State, rotor speeds and vehicle at N samples.
    """
    force, torque = zero_wrench(inputs)
    air = inputs
    for effect in effects:
        velocity = effect.air_velocity(inputs)
        if velocity is not None:
            air = replace(inputs, velocity=velocity)
    for effect in effects:
        if "wrench" in effect.channels:
            f, m = effect.wrench(air if effect.airspeed else inputs)
            force += f
            torque += m
    return force, torque
