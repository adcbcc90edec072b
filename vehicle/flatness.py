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

import numba
import numpy as np
from mavsysid.vehicle.allocation import allocation_pinv
from mavsysid.vehicle.config_types import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.dynamics import ATT, POS, RATE, STATE_DIM, VEL
from mavsysid.vehicle.rotation import continuous_sign_kernel, matrix_to_quat_kernel
from mavsysid.vehicle.trajectory import FlatOutputs

__all__ = ["SAMPLE_RATE", "SAMPLE_SIZE", "FlatState", "flat_sample", "flat_to_state"]


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


#: Layout of the scratch row `flat_sample` fills: ‖a - g‖, R (row-major, columns
#: x_B y_B z_B), ω, ω̇ and the torque J ω̇ + ω × J ω.
SAMPLE_NORM, SAMPLE_R, SAMPLE_RATE, SAMPLE_RATE_DOT, SAMPLE_TORQUE = 0, 1, 10, 13, 16
SAMPLE_SIZE = 19


@numba.njit(cache=True)
def flat_sample(ax: float, ay: float, az: float, jx: float, jy: float, jz: float,
                sx: float, sy: float, sz: float, psi: float, dpsi: float, ddpsi: float,
                J: np.ndarray, out: np.ndarray) -> bool:
    """Flatness at one sample into ``out`` (`SAMPLE_SIZE`,); False at a singular attitude.

    Acceleration a (m/s²), jerk and snap are world ENU; ψ, ψ̇, ψ̈ in rad, rad/s, rad/s²;
    J (3,) the principal inertia, kg m². The planner's feasibility kernel and
    `flat_to_state` share this one implementation.

    Parameters
    ----------
    ax, ay, az : float
        Acceleration, m/s², world ENU.
    jx, jy, jz : float
        Jerk, m/s³.
    sx, sy, sz : float
        Snap, m/s⁴.
    psi, dpsi, ddpsi : float
        Yaw (rad), yaw rate (rad/s), yaw acceleration (rad/s²).
    J : ndarray, shape (3,)
        Principal moments of inertia, kg·m².
    out : ndarray, shape (SAMPLE_SIZE,)
        Receives the sample.
    """
    # Thrust direction: m (a - g) with g = [0, 0, -GRAVITY].
    tx, ty, tz = ax, ay, az + GRAVITY
    norm = np.sqrt(tx * tx + ty * ty + tz * tz)
    if not norm > 1e-9:
        return False
    zx, zy, zz = tx / norm, ty / norm, tz / norm
    cp, sp = np.cos(psi), np.sin(psi)
    # y_B = z_B × x_C / ‖·‖ with x_C = [cos ψ, sin ψ, 0]; x_B = y_B × z_B.
    yx, yy, yz = -zz * sp, zz * cp, zx * sp - zy * cp
    ny = np.sqrt(yx * yx + yy * yy + yz * yz)
    if not ny > 1e-9:
        return False
    yx, yy, yz = yx / ny, yy / ny, yz / ny
    xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    # First derivatives: s ż + ṡ z = jerk, ż = ω_y x - ω_x y.
    ds = zx * jx + zy * jy + zz * jz
    dzx, dzy, dzz = (jx - ds * zx) / norm, (jy - ds * zy) / norm, (jz - ds * zz) / norm
    wx = -(yx * dzx + yy * dzy + yz * dzz)
    wy = xx * dzx + xy * dzy + xz * dzz
    # From d/dt (y_B · x_C) = 0 with ẏ = -ω_z x + ω_x z and ẋ_C = ψ̇ y_C.
    xxc = xx * cp + xy * sp
    zxc = zx * cp + zy * sp
    yyc = -yx * sp + yy * cp
    wz = (wx * zxc + dpsi * yyc) / xxc
    dxx, dxy, dxz = wz * yx - wy * zx, wz * yy - wy * zy, wz * yz - wy * zz
    dyx, dyy, dyz = -wz * xx + wx * zx, -wz * xy + wx * zy, -wz * xz + wx * zz
    # Second derivatives: s z̈ + 2 ṡ ż + s̈ z = snap.
    dds = dzx * jx + dzy * jy + dzz * jz + zx * sx + zy * sy + zz * sz
    cx = (sx - 2.0 * ds * dzx - dds * zx) / norm - wy * dxx + wx * dyx
    cy = (sy - 2.0 * ds * dzy - dds * zy) / norm - wy * dxy + wx * dyy
    cz = (sz - 2.0 * ds * dzz - dds * zz) / norm - wy * dxz + wx * dyz
    dwx = -(yx * cx + yy * cy + yz * cz)
    dwy = xx * cx + xy * cy + xz * cz
    # Time derivative of ω_z (x·x_C) = ω_x (z·x_C) + ψ̇ (y·y_C), with ẏ_C = -ψ̇ x_C.
    lhs_rest = wz * ((dxx * cp + dxy * sp) + dpsi * (-xx * sp + xy * cp))
    rhs = (dwx * zxc + wx * ((dzx * cp + dzy * sp) + dpsi * (-zx * sp + zy * cp))
           + ddpsi * yyc + dpsi * (-dyx * sp + dyy * cp))
    dwz = (rhs - lhs_rest) / xxc
    out[SAMPLE_NORM] = norm
    r = SAMPLE_R
    out[r], out[r + 1], out[r + 2] = xx, yx, zx
    out[r + 3], out[r + 4], out[r + 5] = xy, yy, zy
    out[r + 6], out[r + 7], out[r + 8] = xz, yz, zz
    out[SAMPLE_RATE], out[SAMPLE_RATE + 1], out[SAMPLE_RATE + 2] = wx, wy, wz
    out[SAMPLE_RATE_DOT], out[SAMPLE_RATE_DOT + 1], out[SAMPLE_RATE_DOT + 2] = dwx, dwy, dwz
    # Paper Eq. (allocation), torque side: J ω̇ + ω × J ω.
    out[SAMPLE_TORQUE] = J[0] * dwx + (wy * J[2] * wz - wz * J[1] * wy)
    out[SAMPLE_TORQUE + 1] = J[1] * dwy + (wz * J[0] * wx - wx * J[2] * wz)
    out[SAMPLE_TORQUE + 2] = J[2] * dwz + (wx * J[1] * wy - wy * J[0] * wx)
    return True


@numba.njit(cache=True)
def _flat_states_kernel(acc, jerk, snap, yaw, yaw_rate, yaw_acc, velocity, J, mass, pinv):
    """Every sample of `flat_to_state`; NaN rows where the attitude is singular."""
    S, k = acc.shape[0], pinv.shape[0]
    R = np.full((S, 3, 3), np.nan)
    quat, v_body = np.full((S, 4), np.nan), np.full((S, 3), np.nan)
    omega, domega = np.full((S, 3), np.nan), np.full((S, 3), np.nan)
    torque, thrust, n2 = np.full((S, 3), np.nan), np.full(S, np.nan), np.full((S, k), np.nan)
    f = np.empty(SAMPLE_SIZE)
    for i in range(S):
        if not flat_sample(acc[i, 0], acc[i, 1], acc[i, 2], jerk[i, 0], jerk[i, 1], jerk[i, 2],
                           snap[i, 0], snap[i, 1], snap[i, 2], yaw[i], yaw_rate[i], yaw_acc[i],
                           J, f):
            continue
        for a in range(3):
            for b in range(3):
                R[i, a, b] = f[SAMPLE_R + 3 * a + b]
            omega[i, a] = f[SAMPLE_RATE + a]
            domega[i, a] = f[SAMPLE_RATE_DOT + a]
            torque[i, a] = f[SAMPLE_TORQUE + a]
        for b in range(3):
            v_body[i, b] = R[i, 0, b] * velocity[i, 0] + R[i, 1, b] * velocity[i, 1] \
                + R[i, 2, b] * velocity[i, 2]
        matrix_to_quat_kernel(R[i], quat[i])
        thrust[i] = mass * f[SAMPLE_NORM]
        # Paper Eq. allocation: [T; J ω̇ + ω × J ω] = A n².
        for r in range(k):
            n2[i, r] = (pinv[r, 0] * thrust[i] + pinv[r, 1] * torque[i, 0]
                        + pinv[r, 2] * torque[i, 1] + pinv[r, 3] * torque[i, 2])
    continuous_sign_kernel(quat)  # restarts after a singular (NaN) sample
    return R, quat, v_body, omega, domega, thrust, torque, n2


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
        NaN at samples where the attitude is singular (free fall, or thrust along x_C).
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)

    def column(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=float)

    R, quat, v_body, omega, domega, thrust, torque, n2 = _flat_states_kernel(
        column(flat.acceleration), column(flat.jerk), column(flat.snap), column(flat.yaw),
        column(flat.yaw_rate), column(flat.yaw_acceleration), column(flat.velocity),
        column(theta[3:6]), float(config.mass), allocation_pinv(config, theta))
    return FlatState(
        position=flat.position,
        velocity=flat.velocity,
        velocity_body=v_body,
        rotation=R,
        quaternion=quat,
        body_rates=omega,
        angular_acceleration=domega,
        thrust=thrust,
        torque=torque,
        rotor_speeds_squared=n2,
    )
