"""What an ideal IMU on the vehicle reads: body rates and specific force, at its position.

An accelerometer measures the specific force, the non-gravitational force per unit mass,
f = a − g in the world frame, in its own (body) frame: [0, 0, +9.81] m/s² (FLU) level at
rest, F_B/m at the centre of gravity in flight, where F_B is the body force of
`mavsysid.vehicle.dynamics` (rotor thrust and drag, plus any extra force). An IMU at p
(body FLU, from the CoG) on a rigid body also feels the rotation:

    f_imu = F_B/m + ω̇ × p + ω × (ω × p),    gyro = ω

with ω̇ from Euler's equation (`mavsysid.vehicle.mav_model.euler_acceleration`). The rotor
wrench is the model's one (`mavsysid.vehicle.mav_model.rotor_wrench`). Autopilots log the
same quantities in body FRD (`mavsysid.vehicle.frames.flu_to_frd`): [0, 0, −9.81] level
at rest.
"""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.mav_model import euler_acceleration, rotor_wrench

__all__ = ["imu_reading", "lever_arm_acceleration"]


def lever_arm_acceleration(w: np.ndarray, w_dot: np.ndarray, position: np.ndarray) -> np.ndarray:
    """The specific force an IMU at ``position`` feels beyond the CoG's: ω̇ × p + ω × (ω × p).

    Parameters
    ----------
    w : ndarray, shape (..., 3)
        Body rates ω, rad/s.
    w_dot : ndarray, shape (..., 3)
        Angular acceleration ω̇, rad/s².
    position : array_like, shape (3,) or (..., 3)
        The IMU's offset from the CoG, m, body frame.

    Returns
    -------
    ndarray, shape (..., 3)
        m/s², body frame.
    """
    p = np.asarray(position, dtype=float)
    return np.cross(w_dot, p) + np.cross(w, np.cross(w, p))


def imu_reading(x: np.ndarray, n: np.ndarray, theta: np.ndarray, mass: float,
                rotor_positions: np.ndarray, rotor_directions: np.ndarray,
                force_ext: np.ndarray | None = None, torque_ext: np.ndarray | None = None,
                imu_position: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ideal gyro and accelerometer readings for states and rotor speeds.

    Parameters
    ----------
    x : ndarray, shape (..., 13)
        States [p, v_B, q, ω] (`mavsysid.vehicle.dynamics`).
    n : ndarray, shape (..., k)
        Rotor speeds, rad/s.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI.
    mass : float
        kg.
    rotor_positions : ndarray, shape (k, 3)
        m, body FLU.
    rotor_directions : ndarray, shape (k,)
        ±1.
    force_ext, torque_ext : ndarray, shape (3,) or (..., 3), optional
        Extra body force (N) and torque (N·m), e.g. a truth-side effect's; 0 if None.
    imu_position : array_like, shape (3,), optional
        The IMU's offset from the CoG, m, body FLU; at the CoG if None.

    Returns
    -------
    gyro : ndarray, shape (..., 3)
        ω, rad/s, body FLU.
    accel : ndarray, shape (..., 3)
        Specific force at the IMU, m/s², body FLU.
    """
    x = np.asarray(x, dtype=float)
    v, w = x[..., 3:6], x[..., 10:13]
    force, torque = rotor_wrench(n, theta, rotor_positions, rotor_directions, v, w)
    if force_ext is not None:
        force = force + force_ext
    if torque_ext is not None:
        torque = torque + torque_ext
    accel = force / mass
    if imu_position is not None and np.any(np.asarray(imu_position) != 0.0):
        w_dot = euler_acceleration(torque, w, np.asarray(theta, dtype=float)[3:6])
        accel = accel + lever_arm_acceleration(w, w_dot, imu_position)
    return w.copy(), accel
