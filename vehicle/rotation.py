"""Quaternion and rotation helpers in mavsysid's conventions.

Quaternions are Hamilton, stored scalar first ``[w, x, y, z]``, and rotate body → world.
All functions broadcast over leading dimensions. scipy's `Rotation` is scalar-last;
the conversion happens here and nowhere else.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "exp_kernel",
    "log_kernel",
    "matrix_to_quat",
    "multiply_kernel",
    "quat_conjugate",
    "quat_exp",
    "quat_log",
    "quat_multiply",
    "quat_normalize",
    "quat_to_matrix",
    "skew",
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
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = (q[..., i] for i in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternion ``[w, x, y, z]`` (w ≥ 0) of rotation matrices, shape (..., 3, 3) → (..., 4).

    Parameters
    ----------
    R : ndarray, shape (..., 3, 3)
        Rotation matrices.
    """
    R = np.asarray(R, dtype=float)
    flat = R.reshape(-1, 3, 3)
    q = Rotation.from_matrix(flat).as_quat(scalar_first=True)
    return quat_normalize(q).reshape(*R.shape[:-2], 4)


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
