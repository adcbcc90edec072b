"""Differential flatness: flat outputs → full state, thrust, torques and rotor speeds.

Paper Section "Recovering the Nominal States and Inputs" (after Mellinger & Kumar):
the attitude follows from the thrust direction and yaw, the body rates from jerk and
yaw rate, the angular acceleration from snap and yaw acceleration, and the rotor
speeds from paper Eq. (allocation). Drag is neglected here, as in the paper.

The yaw convention: x_B lies in the plane spanned by z_B and x_C = [cos ψ, sin ψ, 0],
i.e. y_B = (z_B × x_C) / |z_B × x_C|. Body-rate and angular-acceleration expressions
below are exact derivatives of that construction (no small-angle approximation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vehicle.allocation import rotor_speeds_squared
from vehicle.config import GRAVITY, VehicleConfig
from vehicle.dynamics import ATT, POS, RATE, STATE_DIM, VEL
from vehicle.rotation import matrix_to_quat
from vehicle.trajectory import FlatOutputs

__all__ = ["FlatState", "flat_to_state"]


@dataclass(frozen=True)
class FlatState:
    """Full nominal state and inputs along a trajectory, S samples.

    Attributes
    ----------
    position, velocity : ndarray, shape (S, 3)
        World ENU position (m) and velocity (m/s).
    velocity_body : ndarray, shape (S, 3)
        Velocity in the body frame, m/s.
    rotation : ndarray, shape (S, 3, 3)
        R, body → world.
    quaternion : ndarray, shape (S, 4)
        ``[w, x, y, z]`` of R, sign-continuous along the samples.
    body_rates, angular_acceleration : ndarray, shape (S, 3)
        ω (rad/s) and ω̇ (rad/s²) in the body frame.
    thrust : ndarray, shape (S,)
        Collective thrust m |a - g|, N.
    torque : ndarray, shape (S, 3)
        Body torque J ω̇ + ω × J ω, N·m.
    rotor_speeds_squared : ndarray, shape (S, k)
        n² from the allocation, (rad/s)²; negative where the wrench is unachievable.
    """

    position: np.ndarray
    velocity: np.ndarray
    velocity_body: np.ndarray
    rotation: np.ndarray
    quaternion: np.ndarray
    body_rates: np.ndarray
    angular_acceleration: np.ndarray
    thrust: np.ndarray
    torque: np.ndarray
    rotor_speeds_squared: np.ndarray

    @property
    def rotor_speeds(self) -> np.ndarray:
        """Rotor speeds n, rad/s, shape (S, k) (n² clipped at zero first)."""
        return np.sqrt(np.clip(self.rotor_speeds_squared, 0.0, None))

    def states(self) -> np.ndarray:
        """Model states [p, v_B, q, ω], shape (S, 13)."""
        x = np.empty((self.position.shape[0], STATE_DIM))
        x[:, POS] = self.position
        x[:, VEL] = self.velocity_body
        x[:, ATT] = self.quaternion
        x[:, RATE] = self.body_rates
        return x


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _sign_continuous(q: np.ndarray) -> np.ndarray:
    """Flip quaternion signs so consecutive samples lie in the same hemisphere."""
    if q.shape[0] < 2:
        return q
    flips = np.concatenate([[1.0], np.sign(_dot(q[1:], q[:-1]) + 1e-300)])
    return q * np.cumprod(flips)[:, None]


def flat_to_state(
    flat: FlatOutputs, config: VehicleConfig, theta: np.ndarray | None = None
) -> FlatState:
    """Recover the nominal state and rotor speeds from flat outputs.

    Parameters
    ----------
    flat : FlatOutputs
        Position derivatives up to snap and yaw up to its second derivative, S samples.
    config : VehicleConfig
        Mass and rotor geometry.
    theta : ndarray, shape (6,), optional
        Parameters used for inertia and allocation; the config's nominal θ by default.

    Returns
    -------
    FlatState
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)
    J = theta[3:6]
    psi, dpsi, ddpsi = flat.yaw, flat.yaw_rate[:, None], flat.yaw_acceleration[:, None]

    # Thrust direction: m (a - g) with g = [0, 0, -GRAVITY].
    t_vec = flat.acceleration + np.array([0.0, 0.0, GRAVITY])
    s = np.linalg.norm(t_vec, axis=-1, keepdims=True)
    z = t_vec / s
    x_c = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], axis=-1)
    y_c = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], axis=-1)
    y = np.cross(z, x_c)
    y /= np.linalg.norm(y, axis=-1, keepdims=True)
    x = np.cross(y, z)
    R = np.stack([x, y, z], axis=-1)

    # First derivatives: s ż + ṡ z = jerk, ż = ω_y x - ω_x y.
    ds = _dot(z, flat.jerk)[:, None]
    dz = (flat.jerk - ds * z) / s
    wx = -_dot(y, dz)
    wy = _dot(x, dz)
    # From d/dt (y_B · x_C) = 0 with ẏ = -ω_z x + ω_x z and ẋ_C = ψ̇ y_C.
    xxc = _dot(x, x_c)
    wz = (wx * _dot(z, x_c) + dpsi[:, 0] * _dot(y, y_c)) / xxc
    omega = np.stack([wx, wy, wz], axis=-1)
    dx = wz[:, None] * y - wy[:, None] * z
    dy = -wz[:, None] * x + wx[:, None] * z

    # Second derivatives: s z̈ + 2 ṡ ż + s̈ z = snap.
    dds = (_dot(dz, flat.jerk) + _dot(z, flat.snap))[:, None]
    ddz = (flat.snap - 2.0 * ds * dz - dds * z) / s
    c = ddz - wy[:, None] * dx + wx[:, None] * dy
    dwx = -_dot(y, c)
    dwy = _dot(x, c)
    # Time derivative of ω_z (x·x_C) = ω_x (z·x_C) + ψ̇ (y·y_C), with ẏ_C = -ψ̇ x_C.
    lhs_rest = wz * (_dot(dx, x_c) + dpsi[:, 0] * _dot(x, y_c))
    rhs = (
        dwx * _dot(z, x_c)
        + wx * (_dot(dz, x_c) + dpsi[:, 0] * _dot(z, y_c))
        + ddpsi[:, 0] * _dot(y, y_c)
        + dpsi[:, 0] * _dot(dy, y_c)
    )
    dwz = (rhs - lhs_rest) / xxc
    domega = np.stack([dwx, dwy, dwz], axis=-1)

    thrust = config.mass * s[:, 0]
    # Paper Eq. allocation: [T; J ω̇ + ω × J ω] = A n².
    torque = J * domega + np.cross(omega, J * omega)
    n2 = rotor_speeds_squared(np.concatenate([thrust[:, None], torque], axis=-1), config, theta)

    return FlatState(
        position=flat.position,
        velocity=flat.velocity,
        velocity_body=np.einsum("sji,sj->si", R, flat.velocity),
        rotation=R,
        quaternion=_sign_continuous(matrix_to_quat(R)),
        body_rates=omega,
        angular_acceleration=domega,
        thrust=thrust,
        torque=torque,
        rotor_speeds_squared=n2,
    )
