"""Frame conversions at the log boundary and interpolation of pose samples.

Flight logs store MAVLink/PX4/ArduPilot frames: world NED, body FRD. mavsysid uses world
ENU and body FLU (DESIGN.md). With (w, x, y, z) a NED/FRD quaternion (body → world),

    p_enu = (p_ned[1], p_ned[0], −p_ned[2]),
    q_enu_flu = √½ (w + z, x + y, x − y, w − z)

(FIELD-NOTES.md; R_enu_flu = T R_ned_frd B with T the ENU↔NED swap and B = diag(1, −1, −1)).
"""

from __future__ import annotations

import numpy as np

from vehicle.rotation import quat_conjugate, quat_exp, quat_log, quat_multiply

__all__ = [
    "euler_ned_to_quaternion",
    "interpolate_quaternions",
    "ned_to_enu",
    "quaternion_ned_frd_to_enu_flu",
]

_SQRT_HALF = np.sqrt(0.5)


def ned_to_enu(p: np.ndarray) -> np.ndarray:
    """Positions, shape (N, 3), m: world NED → world ENU."""
    p = np.asarray(p, dtype=float)
    return np.stack([p[:, 1], p[:, 0], -p[:, 2]], axis=1)


def quaternion_ned_frd_to_enu_flu(q: np.ndarray) -> np.ndarray:
    """Attitudes, shape (N, 4) ``[w, x, y, z]``: body FRD → world NED to body FLU → world ENU.

    The map is linear and norm-preserving, so a non-unit input stays exactly as far from
    unit norm as it was (the checks judge that afterwards).
    """
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return _SQRT_HALF * np.stack([w + z, x + y, x - y, w - z], axis=1)


def euler_ned_to_quaternion(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Aerospace (Z-Y-X) Euler angles, rad, shape (N,), to NED/FRD quaternions (N, 4).

    q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll), the convention of MAVLink ATTITUDE and of
    ArduPilot's ATT and VISP log messages.
    """
    cr, sr = np.cos(0.5 * np.asarray(roll, float)), np.sin(0.5 * np.asarray(roll, float))
    cp, sp = np.cos(0.5 * np.asarray(pitch, float)), np.sin(0.5 * np.asarray(pitch, float))
    cy, sy = np.cos(0.5 * np.asarray(yaw, float)), np.sin(0.5 * np.asarray(yaw, float))
    return np.stack([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ], axis=1)


def interpolate_quaternions(t: np.ndarray, q: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing, N ≥ 2.
    q : ndarray, shape (N, 4)
        Unit quaternions ``[w, x, y, z]`` at `t`.
    t_new : ndarray, shape (M,)
        Times to interpolate at, s, within ``[t[0], t[-1]]``.

    Returns
    -------
    ndarray, shape (M, 4)
        q(t_new), along the shorter arc between neighbouring samples.
    """
    t_new = np.asarray(t_new, dtype=float)
    i = np.clip(np.searchsorted(t, t_new, side="right") - 1, 0, len(t) - 2)
    s = ((t_new - t[i]) / (t[i + 1] - t[i]))[:, None]
    q0 = q[i]
    # q0 ⊗ Exp(s Log(q0⁻¹ ⊗ q1)); quat_log takes the shorter rotation, so a sign flip
    # between neighbours (q and −q are one attitude) does not send the path the long way.
    delta = quat_log(quat_multiply(quat_conjugate(q0), q[i + 1]))
    return quat_multiply(q0, quat_exp(s * delta))
