"""Named physical effects beyond the paper's model: one definition for truth and model.

Each effect of docs/architecture.md's stable list (``body_drag``, ``rotor_drag_linear``,
``motor_lag``, ``pose_delay``, ``marker_offset``, ``cog_offset``, ``wind``,
``thrust_drift``, ``ground_effect``) is a `ModelEffect` subclass carrying its parameter
values. An effect enters the model through up to three channels:

* ``wrench`` — an extra body-frame force and torque added to the paper's F_B and M_B,
  evaluated on arrays of N samples (`EffectInputs`);
* ``pose`` — the motion-capture system does not report the pose of the model's body
  frame at the stamped time (`ModelEffect.measured_pose`, truth → measurement, and
  `ModelEffect.corrected_pose`, measurement → model);
* ``rotor_speeds`` — the logged rotor speeds are not the speeds acting on the body
  (`ModelEffect.acting_rotor_speeds`).

The simulator's hidden truth (`mavsysid.flight.offline.effects`), a vehicle config's
``[effects.NAME]``
tables, the EKF and the discrepancy workflow all use these definitions, so the effect
that is hidden is exactly the effect that is fitted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from mavsysid.vehicle.rotation import quat_to_matrix

from mavsysid.errors import InputError

__all__ = [
    "EFFECTS",
    "BodyDrag",
    "CogOffset",
    "EffectInputs",
    "EffectParameter",
    "GroundEffect",
    "MarkerOffset",
    "ModelEffect",
    "MotorLag",
    "PoseDelay",
    "RotorDragLinear",
    "ThrustDrift",
    "Wind",
    "effect_from_values",
    "parse_effect",
    "total_wrench",
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
    """

    name: str
    unit: str
    description: str
    scale: float


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
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    rates: np.ndarray
    rotor_speeds: np.ndarray
    theta: np.ndarray
    rotor_positions: np.ndarray

    def rotation(self) -> np.ndarray:
        """R(q) body → world, shape (N, 3, 3)."""
        return quat_to_matrix(self.quaternion)

    def hub_velocities(self) -> np.ndarray:
        """v_B + ω × r_i of every rotor hub, shape (N, k, 3), m/s."""
        return self.velocity[:, None, :] + _cross(self.rates[:, None, :],
                                                    self.rotor_positions[None, :, :])

    def rotor_thrusts(self) -> np.ndarray:
        """c_T n_i², shape (N, k), N."""
        return self.theta[0] * self.rotor_speeds**2


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (size 3), broadcasting; shape of the broadcast.

    np.cross's axis handling costs tens of µs a call, which dominates the simulator's
    per-tick evaluation of one sample; this is the same formula without it.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _zero_wrench(inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
    n = len(inputs.t)
    return np.zeros((n, 3)), np.zeros((n, 3))


def _rotor_wrench(inputs: EffectInputs, forces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum of per-rotor body forces (N, k, 3) acting at the hubs: force and torque (N, 3)."""
    torque = _cross(inputs.rotor_positions[None, :, :], forces).sum(axis=1)
    return forces.sum(axis=1), torque


def _paper_rotor_forces(inputs: EffectInputs) -> np.ndarray:
    """The paper's per-rotor force: thrust c_T n² e_z and its rotor drag (paper Eq. drag)."""
    thrust = inputs.rotor_thrusts()
    hub = inputs.hub_velocities()
    forces = np.empty(hub.shape)
    forces[..., 0] = -thrust * inputs.theta[1] * hub[..., 0]
    forces[..., 1] = -thrust * inputs.theta[1] * hub[..., 1]
    forces[..., 2] = thrust
    return forces


class ModelEffect:
    """Base class: an effect with its parameter values; every channel defaults to none."""

    name: ClassVar[str] = "effect"
    title: ClassVar[str] = ""
    description: ClassVar[str] = ""
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    #: Channels through which the effect enters: a subset of {"wrench", "pose",
    #: "rotor_speeds"}.
    channels: ClassVar[frozenset[str]] = frozenset()

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
        """The same effect with other parameter values, shape (P,)."""
        return type(self)(**dict(zip(self.parameter_names(), map(float, values), strict=True)))

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v:g}" for k, v in self.as_dict().items())
        return f"{type(self).__name__}({inner})"

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and np.array_equal(self.values, other.values)  # type: ignore[attr-defined]

    def __hash__(self) -> int:
        return hash((self.name, tuple(self.values)))

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        """Extra body force (N) and torque (N·m), each of shape (N, 3)."""
        return _zero_wrench(inputs)

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Truth → measurement: the pose reported at times t given the true pose at t.

        Shapes (N,), (N, 3), (N, 4). A delay needs the pose history, so it is applied
        by interpolating over the whole arrays (the simulator keeps a history).
        """
        return position, quaternion

    def corrected_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Measurement → model: times, positions and attitudes of the model's body frame."""
        return t, position, quaternion

    def acting_rotor_speeds(self, t: np.ndarray, logged: np.ndarray) -> np.ndarray:
        """Speeds acting on the body given the logged ones, shape (N, k), rad/s."""
        return logged


class BodyDrag(ModelEffect):
    """Parasitic drag of the airframe, quadratic in airspeed: F_B = −k ‖v_B‖ v_B."""

    name = "body_drag"
    title = "body (parasitic) drag"
    description = ("the airframe's own drag, quadratic in speed and acting on every axis "
                   "(F = -k |v| v at the centre of gravity)")
    parameters = (EffectParameter("k", "kg/m", "drag force per squared airspeed", 0.02),)
    channels = frozenset({"wrench"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        v = inputs.velocity
        force = -self.values[0] * np.linalg.norm(v, axis=1)[:, None] * v
        return force, np.zeros_like(force)


class RotorDragLinear(ModelEffect):
    """Rotor drag linear in rotor speed (RotorS/RotorPy form): F_i = −k n_i P(v_B + ω × r_i)."""

    name = "rotor_drag_linear"
    title = "rotor drag linear in rotor speed"
    description = ("blade flapping and induced drag of each rotor, proportional to its speed "
                   "and to the in-plane hub velocity (F_i = -k n_i (v + w x r_i)_xy)")
    parameters = (EffectParameter("k", "N·s/(m·rad)", "drag force per rotor speed and speed",
                                  1e-4),)
    channels = frozenset({"wrench"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        hub = inputs.hub_velocities()
        forces = -self.values[0] * inputs.rotor_speeds[..., None] * hub
        forces[..., 2] = 0.0
        return _rotor_wrench(inputs, forces)


class MotorLag(ModelEffect):
    """First-order motor lag: the log holds commanded speeds; τ ṅ = n_logged − n acts."""

    name = "motor_lag"
    title = "motor time constant"
    description = ("the logged rotor speeds are commands; the motors follow them with a "
                   "first-order lag of time constant tau")
    parameters = (EffectParameter("tau", "s", "motor time constant", 0.02),)
    channels = frozenset({"rotor_speeds"})

    def acting_rotor_speeds(self, t: np.ndarray, logged: np.ndarray) -> np.ndarray:
        tau = self.values[0]
        if tau <= 0.0 or len(t) < 2:
            return logged
        out = np.empty_like(logged, dtype=float)
        out[0] = logged[0]
        dt = np.diff(t)
        # Exact response of the lag to an input linear between samples (first-order hold).
        a = np.exp(-dt / tau)
        b = 1.0 - tau / dt * (1.0 - a)
        if np.ptp(dt) <= 1e-9 * dt[0]:
            # Uniform steps: the same recursion, y_i = a y_(i-1) + b x_i + (1 - a - b) x_(i-1),
            # as one IIR filter (the loop below costs ~25 ms per call on a 30 s log).
            from scipy.signal import lfilter

            x = np.asarray(logged, dtype=float)
            a0, b0 = a[0], b[0]
            zi = ((a0 + 1.0 - a0 - b0) * x[0])[None, ...]
            out[1:] = lfilter([b0, 1.0 - a0 - b0], [1.0, -a0], x[1:], axis=0, zi=zi)[0]
            return out
        for i in range(1, len(t)):
            out[i] = (a[i - 1] * out[i - 1] + (1.0 - a[i - 1]) * logged[i - 1]
                      + b[i - 1] * (logged[i] - logged[i - 1]))
        return out


class PoseDelay(ModelEffect):
    """The motion-capture pose stamped t is the pose at t − d."""

    name = "pose_delay"
    title = "pose measurement delay"
    description = ("the motion-capture pose arrives late: the pose stamped t was taken at "
                   "t - delay, relative to the rotor speeds")
    parameters = (EffectParameter("delay", "s", "measurement delay", 0.01),)
    channels = frozenset({"pose"})

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        from mavsysid.vehicle.rotation import quat_normalize

        d = self.values[0]
        ts = np.clip(t - d, t[0], t[-1])
        p = np.column_stack([np.interp(ts, t, position[:, i]) for i in range(3)])
        q = np.column_stack([np.interp(ts, t, quaternion[:, i]) for i in range(4)])
        return p, quat_normalize(q)

    def corrected_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return t - self.values[0], position, quaternion


class MarkerOffset(ModelEffect):
    """The tracked point sits at r in the body frame: p_meas = p + R r."""

    name = "marker_offset"
    title = "motion-capture marker offset"
    description = ("the motion-capture body frame's origin is not the vehicle's reference "
                   "point: the reported position is p + R r")
    parameters = (EffectParameter("x", "m", "offset along x_B", 0.01),
                  EffectParameter("y", "m", "offset along y_B", 0.01),
                  EffectParameter("z", "m", "offset along z_B", 0.01))
    channels = frozenset({"pose"})

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        return position + quat_to_matrix(quaternion) @ self.values, quaternion

    def corrected_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return t, position - quat_to_matrix(quaternion) @ self.values, quaternion


class CogOffset(ModelEffect):
    """The centre of gravity sits at c in the body frame of the rotor geometry and the pose.

    The body turns about the CoG, so the rotor forces act on arms r_i − c
    (ΔM = −c × Σ F_i), and the tracked origin is at −c from the CoG (p_meas = p − R c).
    The model state stays the CoG's; the inertia's parallel-axis change (m‖c‖²) is left
    out as second order.
    """

    name = "cog_offset"
    title = "centre-of-gravity offset"
    description = ("the centre of gravity is not where the rotor geometry assumes: the "
                   "rotor forces act on shifted arms and the tracked origin is offset")
    parameters = (EffectParameter("x", "m", "CoG along x_B", 0.005),
                  EffectParameter("y", "m", "CoG along y_B", 0.005),
                  EffectParameter("z", "m", "CoG along z_B", 0.005))
    channels = frozenset({"wrench", "pose"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        c = self.values
        shifted = EffectInputs(inputs.t, inputs.position, inputs.quaternion, inputs.velocity,
                               inputs.rates, inputs.rotor_speeds, inputs.theta,
                               inputs.rotor_positions - c)
        base = _paper_rotor_forces(inputs)
        moved = _paper_rotor_forces(shifted)
        force = (moved - base).sum(axis=1)
        torque = (_cross(shifted.rotor_positions[None], moved)
                  - _cross(inputs.rotor_positions[None], base)).sum(axis=1)
        return force, torque

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        return position - quat_to_matrix(quaternion) @ self.values, quaternion

    def corrected_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return t, position + quat_to_matrix(quaternion) @ self.values, quaternion


class Wind(ModelEffect):
    """Constant horizontal wind w (world ENU): the rotor drag sees airspeed v_B − Rᵀ w.

    The paper's rotor drag has no component along z_B, so a vertical wind is not
    observable through it and is not a parameter.
    """

    name = "wind"
    title = "constant wind"
    description = ("a steady wind: the rotors' drag acts on the airspeed, not the speed "
                   "over ground")
    parameters = (EffectParameter("x", "m/s", "wind towards +x (east)", 0.5),
                  EffectParameter("y", "m/s", "wind towards +y (north)", 0.5))
    channels = frozenset({"wrench"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        w_body = np.einsum("nji,j->ni", inputs.rotation(), np.append(self.values, 0.0))
        k = inputs.rotor_thrusts() * inputs.theta[1]
        forces = np.zeros(k.shape + (3,))
        forces[..., 0] = k * w_body[:, None, 0]
        forces[..., 1] = k * w_body[:, None, 1]
        return _rotor_wrench(inputs, forces)


class ThrustDrift(ModelEffect):
    """c_T drifting linearly in time (battery sag): c_T(t) = c_T (1 + rate · t)."""

    name = "thrust_drift"
    title = "thrust drifting during the flight"
    description = ("the thrust per squared rotor speed changes during the flight, as when "
                   "the battery sags: c_T(t) = c_T (1 + rate t)")
    parameters = (EffectParameter("rate", "1/s", "relative change of c_T per second", 1e-3),)
    channels = frozenset({"wrench"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        forces = _paper_rotor_forces(inputs) * (self.values[0] * inputs.t)[:, None, None]
        return _rotor_wrench(inputs, forces)


class GroundEffect(ModelEffect):
    """Cheeseman–Bennett ground effect: T_i / T_i,∞ = 1 / (1 − (ρ / 4h_i)²).

    h_i is the height of rotor i above the ground plane z = 0, clipped at ρ / 2 so the
    factor stays ≤ 4/3.
    """

    name = "ground_effect"
    title = "ground effect"
    description = ("near the ground each rotor makes more thrust: T/T_inf = "
                   "1/(1 - (rho/4h)^2), rho the rotor radius, h the rotor's height")
    parameters = (EffectParameter("rotor_radius", "m", "rotor radius ρ", 0.1),)
    channels = frozenset({"wrench"})

    def gain(self, inputs: EffectInputs) -> np.ndarray:
        """Extra thrust fraction of every rotor, shape (N, k)."""
        rho = abs(self.values[0])
        hubs = inputs.position[:, None, :] + np.einsum(
            "nij,kj->nki", inputs.rotation(), inputs.rotor_positions)
        h = np.maximum(hubs[..., 2], 0.5 * rho + 1e-9)
        return 1.0 / (1.0 - (rho / (4.0 * h)) ** 2) - 1.0

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        forces = np.zeros(inputs.rotor_speeds.shape + (3,))
        forces[..., 2] = self.gain(inputs) * inputs.rotor_thrusts()
        return _rotor_wrench(inputs, forces)


#: The catalogue, by stable name (docs/architecture.md).
EFFECTS: dict[str, type[ModelEffect]] = {
    cls.name: cls for cls in (BodyDrag, RotorDragLinear, MotorLag, PoseDelay, MarkerOffset,
                              CogOffset, Wind, ThrustDrift, GroundEffect)
}


def effect_from_values(name: str, values: dict[str, float]) -> ModelEffect:
    """An effect by stable name with parameter values by name (missing ones are 0)."""
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name!r}; expected one of {', '.join(EFFECTS)}")
    return EFFECTS[name](**values)


def parse_effect(text: str) -> ModelEffect:
    """``NAME:KEY=VALUE,KEY=VALUE`` (as ``--hidden-effect motor_lag:tau=0.04``)."""
    name, _, rest = text.partition(":")
    values: dict[str, float] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        try:
            if not eq:
                raise ValueError
            values[key.strip()] = float(value)
        except ValueError:
            raise InputError(f"effect {text!r}: {item!r} is not KEY=NUMBER") from None
    return effect_from_values(name.strip(), values)


def total_wrench(effects: tuple[ModelEffect, ...] | list[ModelEffect], inputs: EffectInputs
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Sum of the wrenches of ``effects`` at ``inputs``: force and torque (N, 3) each."""
    force, torque = _zero_wrench(inputs)
    for effect in effects:
        if "wrench" in effect.channels:
            f, m = effect.wrench(inputs)
            force += f
            torque += m
    return force, torque
