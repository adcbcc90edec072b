"""Named physical effects beyond the paper's model: one definition for truth and model.

Each effect of the catalogue (`EFFECTS`, docs/architecture.md's stable names) is a
`ModelEffect` subclass carrying its parameter values, and everything else about it: its
parameters with their units, scales and signs, the channels it enters by, and, for a
one-parameter effect the diagnosis searches by profile, the search range. A new effect is
a class here, its entry in `EFFECTS` and its row in docs/architecture.md's table. An effect
enters the model through up to three channels:

* ``wrench`` — an extra body-frame force and torque added to the paper's F_B and M_B,
  evaluated on arrays of N samples (`EffectInputs`);
* ``pose`` — the motion-capture system does not report the pose of the model's body
  frame at the stamped time (`ModelEffect.measured_pose`, truth → measurement, and
  `ModelEffect.corrected_pose`, measurement → model);
* ``rotor_speeds`` — the logged rotor speeds are not the speeds acting on the body
  (`ModelEffect.acting_rotor_speeds`).

The simulator's hidden truth (`mavsysid.flight.offline.effects`), a vehicle config's
``[effects.NAME]`` tables, the EKF and the discrepancy workflow all use these
definitions, so the effect that is hidden is exactly the effect that is fitted. The base
class and the effect inputs live in `mavsysid.vehicle.effect_base`; they are re-exported
here so that this module is the one entry point to the effects.
"""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.effect_base import (
    EffectInputs,
    EffectParameter,
    ModelEffect,
    hub_forces_wrench,
    rotor_force_wrench,
    time_derivative,
    total_wrench,
)
from mavsysid.vehicle.rotation import quat_normalize, quat_to_matrix

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
    "RotorInertia",
    "RotorSpeedLag",
    "ThrustDrift",
    "Wind",
    "effect_from_values",
    "lag_step",
    "parse_effect",
    "total_wrench",
]


class BodyDrag(ModelEffect):
    """Parasitic drag of the airframe, quadratic in airspeed: F_B = −k ‖v_B‖ v_B."""

    name = "body_drag"
    title = "body (parasitic) drag"
    description = ("the airframe's own drag, quadratic in speed and acting on every axis "
                   "(F = -k |v| v at the centre of gravity)")
    parameters = (EffectParameter("k", "kg/m", "drag force per squared airspeed", 0.02,
                                  "nonnegative"),)
    channels = frozenset({"wrench"})
    airspeed = True

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        v = inputs.velocity
        force = -self.values[0] * np.linalg.norm(v, axis=1)[:, None] * v
        return force, np.zeros_like(force)


class RotorDragLinear(ModelEffect):
    """Rotor drag linear in rotor speed (RotorS/RotorPy form): F_i = −n_i K (v_B + ω × r_i).

    K = diag(k, k, k_z): k is the in-plane drag of blade flapping and induced drag (the
    H-force), k_z the loss of thrust with the axial inflow through the rotor (induced
    inflow), which also damps roll and pitch through the arms. RotorPy's rotor drag matrix
    (its ``k_d``, ``k_z``) exactly.
    """

    name = "rotor_drag_linear"
    title = "rotor drag linear in rotor speed"
    description = ("blade flapping and induced drag of each rotor, proportional to its speed "
                   "and to the hub velocity: in plane (k) and along the rotor axis (k_z, "
                   "the induced inflow), F_i = -n_i diag(k, k, k_z) (v + w x r_i)")
    parameters = (EffectParameter("k", "N·s/(m·rad)", "in-plane drag force per rotor speed "
                                  "and speed", 1e-4, "nonnegative"),
                  EffectParameter("k_z", "N·s/(m·rad)", "axial (inflow) force per rotor speed "
                                  "and speed", 1e-4, "nonnegative"))
    channels = frozenset({"wrench"})
    airspeed = True

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        hub = inputs.hub_velocities()
        forces = -inputs.rotor_speeds[..., None] * hub * np.array(
            [self.values[0], self.values[0], self.values[1]])
        return hub_forces_wrench(inputs, forces)


def lag_step(dt: float | np.ndarray, tau: float, y: np.ndarray, x: np.ndarray,
             x_next: np.ndarray) -> np.ndarray:
    """One step of τ ẏ = x − y with x linear over the step (first-order hold), exact.

    Parameters
    ----------
    dt : float or ndarray
        Step, s (> 0).
    tau : float
        Time constant, s; ≤ 0 follows x at once.
    y, x, x_next : ndarray
        Output now, input now and input at the step's end (same shapes).

    Returns
    -------
    ndarray
        The output at the step's end.
    """
    if tau <= 0.0:
        return np.asarray(x_next, dtype=float)
    a = np.exp(-dt / tau)
    b = 1.0 - tau / dt * (1.0 - a)
    return a * y + (1.0 - a) * x + b * (x_next - x)


class MotorLag(ModelEffect):
    """First-order motor lag: the log holds commanded speeds; τ ṅ = n_logged − n acts."""

    name = "motor_lag"
    title = "motor time constant"
    description = ("the logged rotor speeds are commands; the motors follow them with a "
                   "first-order lag of time constant tau")
    parameters = (EffectParameter("tau", "s", "motor time constant", 0.02, "nonnegative"),)
    channels = frozenset({"rotor_speeds"})
    profile = (0.0, 0.1201, 0.006)

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
            # Imported here: scipy.signal adds ~0.5 s to every command's start-up, and only
            # the discrepancy workflow reaches this branch.
            from scipy.signal import lfilter

            x = np.asarray(logged, dtype=float)
            a0, b0 = a[0], b[0]
            zi = ((a0 + 1.0 - a0 - b0) * x[0])[None, ...]
            out[1:] = lfilter([b0, 1.0 - a0 - b0], [1.0, -a0], x[1:], axis=0, zi=zi)[0]
            return out
        for i in range(1, len(t)):
            out[i] = lag_step(dt[i - 1], tau, out[i - 1], logged[i - 1], logged[i])
        return out


class PoseDelay(ModelEffect):
    """The motion-capture pose stamped t is the pose at t − d."""

    name = "pose_delay"
    title = "pose measurement delay"
    description = ("the motion-capture pose arrives late: the pose stamped t was taken at "
                   "t - delay, relative to the rotor speeds")
    parameters = (EffectParameter("delay", "s", "measurement delay", 0.01),)
    channels = frozenset({"pose"})
    profile = (0.0, 0.0801, 0.005)

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
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
        moved_force, moved_torque = rotor_force_wrench(
            inputs, rotor_positions=inputs.rotor_positions - self.values)
        force, torque = rotor_force_wrench(inputs)
        return moved_force - force, moved_torque - torque

    def measured_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        return position - quat_to_matrix(quaternion) @ self.values, quaternion

    def corrected_pose(self, t: np.ndarray, position: np.ndarray, quaternion: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return t, position + quat_to_matrix(quaternion) @ self.values, quaternion


class Wind(ModelEffect):
    """Constant horizontal wind w (world ENU): the drags see the airspeed v_B − Rᵀ w.

    Its wrench is the change of the paper's rotor drag; the airspeed effects in the same
    model (body drag, linear rotor drag) see the wind too (`total_wrench`). The paper's
    rotor drag has no component along z_B, so a vertical wind is not observable through it
    and is not a parameter.
    """

    name = "wind"
    title = "constant wind"
    description = ("a steady wind: the rotors' drag acts on the airspeed, not the speed "
                   "over ground")
    parameters = (EffectParameter("x", "m/s", "wind towards +x (east)", 0.5),
                  EffectParameter("y", "m/s", "wind towards +y (north)", 0.5))
    channels = frozenset({"wrench"})

    def air_velocity(self, inputs: EffectInputs) -> np.ndarray:
        w_body = np.einsum("nji,j->ni", inputs.rotation(), np.append(self.values, 0.0))
        return inputs.velocity - w_body

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        # The paper's rotor drag at the airspeed v_B − Rᵀ w, less the model's at v_B (the
        # airspeed effects see the wind through `total_wrench`).
        air_force, air_torque = rotor_force_wrench(inputs, velocity=self.air_velocity(inputs))
        force, torque = rotor_force_wrench(inputs)
        return air_force - force, air_torque - torque


class ThrustDrift(ModelEffect):
    """c_T drifting linearly in time (battery sag): c_T(t) = c_T (1 + rate · t)."""

    name = "thrust_drift"
    title = "thrust drifting during the flight"
    description = ("the thrust per squared rotor speed changes during the flight, as when "
                   "the battery sags: c_T(t) = c_T (1 + rate t)")
    parameters = (EffectParameter("rate", "1/s", "relative change of c_T per second", 1e-3),)
    channels = frozenset({"wrench"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        force, torque = rotor_force_wrench(inputs)
        scale = (self.values[0] * inputs.t)[:, None]
        return force * scale, torque * scale


class GroundEffect(ModelEffect):
    """Cheeseman–Bennett ground effect: T_i / T_i,∞ = 1 / (1 − (ρ / 4h_i)²).

    h_i is the height of rotor i above the ground plane z = 0, clipped at ρ / 2 so the
    factor stays ≤ 4/3.
    """

    name = "ground_effect"
    title = "ground effect"
    description = ("near the ground each rotor makes more thrust: T/T_inf = "
                   "1/(1 - (rho/4h)^2), rho the rotor radius, h the rotor's height")
    parameters = (EffectParameter("rotor_radius", "m", "rotor radius ρ", 0.1, "positive"),)
    channels = frozenset({"wrench"})
    profile = (0.0, 0.2501, 0.0125)

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
        return hub_forces_wrench(inputs, forces)


class RotorInertia(ModelEffect):
    """The rotors' own inertia J_r: spinning rotor i up takes a torque whose reaction on the
    body is −ε_i J_r ṅ_i about z_B, beside the drag moment −ε_i c_M n_i².

    Both act about the rotor axis with the same sign per rotor, so the yaw channel leads:
    the body yaws as the rotors accelerate, before the drag moments change (the yaw rate
    follows the motor command more than the rotor speed). J_r is rotor and motor bell
    together; the rotors' gyroscopic moment (ω × ε_i J_r n_i z_B) is left out: its sum over
    a balanced vehicle's rotors is about zero (Σ ε_i n_i ≈ 0).
    """

    name = "rotor_inertia"
    title = "rotor inertia"
    description = ("each rotor's moment of inertia J_r: accelerating a rotor turns the body "
                   "the other way, a yaw torque -sum eps_i J_r dn_i/dt")
    parameters = (EffectParameter("J_r", "kg·m²", "moment of inertia of one rotor and its "
                                  "motor bell about its axis", 1e-5, "nonnegative"),)
    channels = frozenset({"wrench"})

    def wrench(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        force = np.zeros((len(inputs.t), 3))
        torque = np.zeros_like(force)
        if inputs.rotor_directions is not None:
            eps = np.asarray(inputs.rotor_directions, dtype=float)
            torque[:, 2] = -self.values[0] * (inputs.rotor_accelerations() @ eps)
        return force, torque


class RotorSpeedLag(ModelEffect):
    """The logged rotor speeds lag the true ones: τ ṅ_logged = n − n_logged.

    A speed sensor that averages (an RPM deck counting commutations, an ESC's telemetry
    filter) reports a first-order lag of the speed acting on the body; its exact inverse
    n = n_logged + τ ṅ_logged is what acts. The opposite of `MotorLag`: there the body
    follows the logged speeds late, here the log follows the body late.
    """

    name = "rotor_speed_lag"
    title = "rotor-speed sensing lag"
    description = ("the measured rotor speeds lag the true ones with a first-order lag of "
                   "time constant tau: the speeds acting are n_logged + tau dn_logged/dt")
    parameters = (EffectParameter("tau", "s", "time constant of the speed measurement",
                                  0.01, "nonnegative"),)
    channels = frozenset({"rotor_speeds"})
    # A lead of the logged speeds' own: negative values would be a motor lag.
    profile = (0.0, 0.0601, 0.004)

    def acting_rotor_speeds(self, t: np.ndarray, logged: np.ndarray) -> np.ndarray:
        tau = self.values[0]
        if tau == 0.0:
            return logged
        return logged + tau * time_derivative(t, logged)

    def logged_step(self, dt: float, logged: np.ndarray, acting: np.ndarray,
                    acting_next: np.ndarray) -> np.ndarray:
        """Acting → logged over one step dt, s: the next logged speeds (k,), rad/s.

        Parameters
        ----------
        dt : float
            Step, s.
        logged : ndarray, shape (k,)
            Logged rotor speeds at the step's start, rad/s.
        acting : ndarray, shape (k,)
            Acting rotor speeds at the step's start, rad/s.
        acting_next : ndarray, shape (k,)
            Acting rotor speeds at the step's end, rad/s (linear in between).
        """
        return lag_step(dt, float(self.values[0]), logged, acting, acting_next)


#: The catalogue, by stable name (docs/architecture.md).
EFFECTS: dict[str, type[ModelEffect]] = {
    cls.name: cls for cls in (BodyDrag, RotorDragLinear, MotorLag, PoseDelay, MarkerOffset,
                              CogOffset, Wind, ThrustDrift, GroundEffect, RotorInertia,
                              RotorSpeedLag)
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
