"""Quaternion and rotation helpers in mavsysid's conventions, each written once.

Quaternions are Hamilton, stored scalar first ``[w, x, y, z]``, and rotate body → world.
The numpy functions broadcast over leading dimensions; the ``*_kernel`` functions are their
single-sample forms for numba code (the numpy forms of q → R and R → q loop over them, so
each formula is written once). Also here: a quaternion sequence made sign-continuous,
Euler angles and yaw of a quaternion, angle wrapping, and slerp between samples.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "continuous_sign",
    "exp_kernel",
    "interpolate_quaternions",
    "log_kernel",
    "matrix_to_quat",
    "matrix_to_quat_kernel",
    "multiply_kernel",
    "quat_conjugate",
    "quat_exp",
    "quat_log",
    "quat_multiply",
    "quat_normalize",
    "quat_to_euler",
    "quat_to_matrix",
    "quat_yaw",
    "rotation_kernel",
    "skew",
    "wrap_angle",
    "wrap_angle_kernel",
]


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]×, shape (..., 3, 3), such that [v]× u = v × u.

    Parameters
    ----------
    v : ndarray, shape (..., 3)
        Vectors.
    """
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q of quaternions ``[w, x, y, z]``, shape (..., 4).

    Parameters
    ----------
    p, q : ndarray, shape (..., 4)
        Quaternions [w, x, y, z].
    """
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - np.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + np.cross(pv, qv)
    return np.concatenate([w, v], axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion), shape (..., 4).

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Quaternions [w, x, y, z].
    """
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion with non-negative scalar part, shape (..., 4).

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Quaternions [w, x, y, z].
    """
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix R(q), body → world, shape (..., 3, 3). q need not be normalised.

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Quaternions [w, x, y, z].
    """
    q = np.asarray(q, dtype=float)
    flat = np.ascontiguousarray(q.reshape(-1, 4))
    out = np.empty((flat.shape[0], 3, 3))
    _matrix_batch(flat, out)
    return out.reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternion ``[w, x, y, z]`` (w ≥ 0) of rotation matrices, shape (..., 3, 3) → (..., 4).

    Parameters
    ----------
    R : ndarray, shape (..., 3, 3)
        Rotation matrices.
    """
    R = np.asarray(R, dtype=float)
    flat = np.ascontiguousarray(R.reshape(-1, 3, 3))
    out = np.empty((flat.shape[0], 4))
    _quat_batch(flat, out)
    return out.reshape(*R.shape[:-2], 4)


def continuous_sign(q: np.ndarray) -> np.ndarray:
    """A quaternion sequence with signs flipped so neighbours are on the same side, (N, 4).

    q and −q are one attitude but not one signal: before a quaternion sequence is smoothed,
    differentiated or interpolated component by component, each sample takes the sign that
    makes its dot product with the previous one non-negative. Returns a new array.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Quaternions [w, x, y, z] in time order.
    """
    q = np.array(q, dtype=float)
    if q.shape[0] > 1:
        flips = np.cumsum(np.r_[False, np.sum(q[1:] * q[:-1], axis=1) < 0.0]) % 2 == 1
        q[flips] *= -1.0
    return q


def quat_to_euler(q: np.ndarray) -> np.ndarray:
    """Roll, pitch and yaw (rad; Z-Y-X intrinsic, yaw about the world z), shape (..., 3).

    The same angles in any frame pair whose quaternion is given: ENU/FLU gives the heading
    of x_B from east, counter-clockwise; NED/FRD the autopilots' roll, pitch and yaw.

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Quaternions [w, x, y, z] (normalised here).
    """
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = (q[..., i] for i in range(4))
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def quat_yaw(q: np.ndarray) -> np.ndarray:
    """Yaw of quaternions (rad, in (−π, π]), shape (...); `quat_to_euler`'s third angle.

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Quaternions [w, x, y, z].
    """
    return quat_to_euler(q)[..., 2]


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Angle wrapped into [−π, π), rad, shape of ``angle``.

    Parameters
    ----------
    angle : float or ndarray
        rad.
    """
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


#: `wrap_angle` for numba code (the same function compiled).
wrap_angle_kernel = numba.njit(cache=True)(wrap_angle)


def interpolate_quaternions(t: np.ndarray, q: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation (slerp) of unit quaternions between their samples.

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


def quat_exp(rotvec: np.ndarray) -> np.ndarray:
    """Exp: rotation vector (rad, shape (..., 3)) → unit quaternion, shape (..., 4).

    Parameters
    ----------
    rotvec : ndarray, shape (..., 3)
        Rotation vectors, rad.
    """
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(θ/2)/θ with its Taylor series near zero, where the quotient loses precision.
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    sinc = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / safe)
    return np.concatenate([np.cos(half), sinc * rotvec], axis=-1)


def quat_log(q: np.ndarray) -> np.ndarray:
    """Log: unit quaternion (shape (..., 4)) → rotation vector in rad, shape (..., 3).

    The shorter of the two equivalent rotations is returned (angle ≤ π).

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        Unit quaternions [w, x, y, z].
    """
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., :1] < 0.0, -q, q)
    w = q[..., :1]
    v = q[..., 1:]
    vnorm = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(vnorm, w)
    small = vnorm < 1e-8
    safe = np.where(small, 1.0, vnorm)
    # θ / sin(θ/2) → 2 / w (1 + …) near zero; 2/w is exact to O(|v|²).
    scale = np.where(small, 2.0 / w, angle / safe)
    return scale * v


# Scalar versions for compiled loops (the EKF and batch estimator), same conventions.


@numba.njit(cache=True)
def multiply_kernel(p, q):
    """p ⊗ q for single quaternions (4,), for numba code.

    Parameters
    ----------
    p, q : ndarray, shape (4,)
        Quaternions [w, x, y, z].
    """
    return np.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    ])


@numba.njit(cache=True)
def exp_kernel(v):
    """Exp of one rotation vector (3,) → unit quaternion (4,), for numba code.

    Parameters
    ----------
    v : ndarray, shape (3,)
        Rotation vector, rad.
    """
    angle = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    sinc = 0.5 - angle * angle / 48.0 if angle < 0.0001 else np.sin(0.5 * angle) / angle
    return np.array([np.cos(0.5 * angle), sinc * v[0], sinc * v[1], sinc * v[2]])


@numba.njit(cache=True)
def log_kernel(q):
    """Log of one unit quaternion (4,) → rotation vector (3,) with angle ≤ π, for numba code.

    Parameters
    ----------
    q : ndarray, shape (4,)
        Unit quaternion [w, x, y, z].
    """
    sign = -1.0 if q[0] < 0.0 else 1.0
    w = sign * q[0]
    vn = np.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    scale = 2.0 / w if vn < 1e-08 else 2.0 * np.arctan2(vn, w) / vn
    return sign * scale * q[1:4]


@numba.njit(cache=True)
def rotation_kernel(q):
    """R(q), body → world, as a (3, 3) array, for numba code; q (4,) need not be unit.

    Parameters
    ----------
    q : ndarray, shape (4,)
        Quaternion [w, x, y, z].
    """
    inv = 1.0 / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    w, x, y, z = q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - w * z)
    R[0, 2] = 2.0 * (x * z + w * y)
    R[1, 0] = 2.0 * (x * y + w * z)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - w * x)
    R[2, 0] = 2.0 * (x * z - w * y)
    R[2, 1] = 2.0 * (y * z + w * x)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


@numba.njit(cache=True)
def matrix_to_quat_kernel(R, q):
    """Unit quaternion [w, x, y, z] of a rotation matrix (Shepperd's branch choice), w ≥ 0,
    into ``q`` (4,), for numba code.

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        Rotation matrix.
    q : ndarray, shape (4,)
        Receives the quaternion.
    """
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace >= R[0, 0] and trace >= R[1, 1] and trace >= R[2, 2]:
        q[0] = 1.0 + trace
        q[1], q[2], q[3] = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    elif R[0, 0] >= R[1, 1] and R[0, 0] >= R[2, 2]:
        q[1] = 1.0 + R[0, 0] - R[1, 1] - R[2, 2]
        q[0], q[2], q[3] = R[2, 1] - R[1, 2], R[0, 1] + R[1, 0], R[0, 2] + R[2, 0]
    elif R[1, 1] >= R[2, 2]:
        q[2] = 1.0 + R[1, 1] - R[0, 0] - R[2, 2]
        q[0], q[1], q[3] = R[0, 2] - R[2, 0], R[0, 1] + R[1, 0], R[1, 2] + R[2, 1]
    else:
        q[3] = 1.0 + R[2, 2] - R[0, 0] - R[1, 1]
        q[0], q[1], q[2] = R[1, 0] - R[0, 1], R[0, 2] + R[2, 0], R[1, 2] + R[2, 1]
    scale = 1.0 / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[0] < 0.0:
        scale = -scale
    for i in range(4):
        q[i] *= scale


@numba.njit(cache=True)
def _matrix_batch(Q, out):
    for i in range(Q.shape[0]):
        out[i] = rotation_kernel(Q[i])


@numba.njit(cache=True)
def _quat_batch(R, out):
    for i in range(R.shape[0]):
        matrix_to_quat_kernel(R[i], out[i])
