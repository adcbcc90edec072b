"""Quaternion and rotation helpers in mavsysid's conventions, each written once.

Quaternions are Hamilton, stored scalar first ``[w, x, y, z]``, and rotate body → world.
The numpy functions broadcast over leading dimensions. For numba code there are single-sample
forms: the ``*_tuple`` functions take arrays or tuples alike and return tuples, so nothing
is allocated (a closed loop calls them every tick); the ``*_kernel`` functions return or
fill arrays and are built on them (as are the numpy forms of q → R, R → q and sign
continuity), so each formula is written once. Also here: a vector rotated by a quaternion,
a quaternion sequence made sign-continuous, Euler angles and yaw of a quaternion, angle
wrapping, and slerp between samples.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "conjugate_tuple",
    "continuous_sign",
    "continuous_sign_kernel",
    "exp_kernel",
    "exp_tuple",
    "interpolate_quaternions",
    "log_kernel",
    "log_tuple",
    "matrix_to_quat",
    "matrix_to_quat_kernel",
    "matrix_to_quat_tuple",
    "multiply_kernel",
    "multiply_tuple",
    "normalized_tuple",
    "quat_conjugate",
    "quat_exp",
    "quat_log",
    "quat_multiply",
    "quat_normalize",
    "quat_to_euler",
    "quat_to_matrix",
    "quat_yaw",
    "rotate_inverse_tuple",
    "rotate_tuple",
    "rotation_kernel",
    "skew",
    "slerp_tuple",
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
    continuous_sign_kernel(q)
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


# Single-sample forms for numba code, same conventions. The tuple forms index their inputs
# (arrays or tuples) and return tuples: no allocation per call.


@numba.njit(cache=True)
def multiply_tuple(p, q):
    """p ⊗ q of single quaternions, as a tuple (w, x, y, z), for numba code.

    Parameters
    ----------
    p, q : ndarray or tuple, shape (4,)
        Quaternions [w, x, y, z].
    """
    return (p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
            p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
            p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
            p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0])


@numba.njit(cache=True)
def conjugate_tuple(q):
    """Conjugate (the inverse of a unit quaternion), as a tuple, for numba code.

    Parameters
    ----------
    q : ndarray or tuple, shape (4,)
        Quaternion [w, x, y, z].
    """
    return (q[0], -q[1], -q[2], -q[3])


@numba.njit(cache=True)
def normalized_tuple(q):
    """``q`` scaled to unit length, its sign kept (unlike `quat_normalize`), as a tuple.

    Parameters
    ----------
    q : ndarray or tuple, shape (4,)
        Quaternion [w, x, y, z], not zero.
    """
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@numba.njit(cache=True)
def exp_tuple(v):
    """Exp of one rotation vector → unit quaternion, as a tuple, for numba code.

    Parameters
    ----------
    v : ndarray or tuple, shape (3,)
        Rotation vector, rad.
    """
    angle = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    # sin(θ/2)/θ with its Taylor series near zero, where the quotient loses precision.
    sinc = 0.5 - angle * angle / 48.0 if angle < 0.0001 else np.sin(0.5 * angle) / angle
    return (np.cos(0.5 * angle), sinc * v[0], sinc * v[1], sinc * v[2])


@numba.njit(cache=True)
def log_tuple(q):
    """Log of one unit quaternion → rotation vector (rad, angle ≤ π), as a tuple.

    Parameters
    ----------
    q : ndarray or tuple, shape (4,)
        Unit quaternion [w, x, y, z].
    """
    sign = -1.0 if q[0] < 0.0 else 1.0
    w = sign * q[0]
    vn = np.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    # θ / sin(θ/2) → 2 / w (1 + …) near zero; 2/w is exact to O(|v|²).
    scale = sign * (2.0 / w if vn < 1e-08 else 2.0 * np.arctan2(vn, w) / vn)
    return (scale * q[1], scale * q[2], scale * q[3])


@numba.njit(cache=True)
def rotate_tuple(q, v):
    """R(q) v without forming R, as a tuple, for numba code.

    Parameters
    ----------
    q : ndarray or tuple, shape (4,)
        Unit quaternion [w, x, y, z].
    v : ndarray or tuple, shape (3,)
        The vector.
    """
    w, a, b, c = q[0], q[1], q[2], q[3]
    x, y, z = v[0], v[1], v[2]
    # v + w t + u × t with t = 2 u × v, u the vector part.
    tx, ty, tz = 2.0 * (b * z - c * y), 2.0 * (c * x - a * z), 2.0 * (a * y - b * x)
    return (x + w * tx + b * tz - c * ty, y + w * ty + c * tx - a * tz,
            z + w * tz + a * ty - b * tx)


@numba.njit(cache=True)
def rotate_inverse_tuple(q, v):
    """R(q)ᵀ v (the vector in the frame q rotates from) without forming R, as a tuple.

    Parameters
    ----------
    q, v
        As for `rotate_tuple`.
    """
    return rotate_tuple(conjugate_tuple(q), v)


@numba.njit(cache=True)
def slerp_tuple(q0, q1, s):
    """q0 ⊗ Exp(s Log(q0⁻¹ ⊗ q1)): ``s`` of the way from q0 to q1 along the shorter arc.

    Parameters
    ----------
    q0, q1 : ndarray or tuple, shape (4,)
        Unit quaternions [w, x, y, z].
    s : float
        Fraction of the way, 0 at q0 and 1 at q1.
    """
    d = log_tuple(multiply_tuple(conjugate_tuple(q0), q1))
    return multiply_tuple(q0, exp_tuple((s * d[0], s * d[1], s * d[2])))


@numba.njit(cache=True)
def matrix_to_quat_tuple(R):
    """Unit quaternion (w, x, y, z), w ≥ 0, of a rotation matrix (Shepperd's branch choice:
    accurate at every angle), as a tuple, for numba code.

    Parameters
    ----------
    R : ndarray or tuple of 3 rows, shape (3, 3)
        Rotation matrix, indexed ``R[i][j]``.
    """
    r00, r01, r02 = R[0][0], R[0][1], R[0][2]
    r10, r11, r12 = R[1][0], R[1][1], R[1][2]
    r20, r21, r22 = R[2][0], R[2][1], R[2][2]
    trace = r00 + r11 + r22
    if trace >= r00 and trace >= r11 and trace >= r22:
        w, x, y, z = 1.0 + trace, r21 - r12, r02 - r20, r10 - r01
    elif r00 >= r11 and r00 >= r22:
        w, x, y, z = r21 - r12, 1.0 + r00 - r11 - r22, r01 + r10, r02 + r20
    elif r11 >= r22:
        w, x, y, z = r02 - r20, r01 + r10, 1.0 + r11 - r00 - r22, r12 + r21
    else:
        w, x, y, z = r10 - r01, r02 + r20, r12 + r21, 1.0 + r22 - r00 - r11
    scale = 1.0 / np.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        scale = -scale
    return (w * scale, x * scale, y * scale, z * scale)


@numba.njit(cache=True)
def multiply_kernel(p, q):
    """p ⊗ q for single quaternions (4,), as an array, for numba code.

    Parameters
    ----------
    p, q : ndarray, shape (4,)
        Quaternions [w, x, y, z].
    """
    return np.array(multiply_tuple(p, q))


@numba.njit(cache=True)
def exp_kernel(v):
    """Exp of one rotation vector (3,) → unit quaternion (4,), as an array, for numba code.

    Parameters
    ----------
    v : ndarray, shape (3,)
        Rotation vector, rad.
    """
    return np.array(exp_tuple(v))


@numba.njit(cache=True)
def log_kernel(q):
    """Log of one unit quaternion (4,) → rotation vector (3,) with angle ≤ π, as an array,
    for numba code.

    Parameters
    ----------
    q : ndarray, shape (4,)
        Unit quaternion [w, x, y, z].
    """
    return np.array(log_tuple(q))


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
    """Unit quaternion [w, x, y, z] (w ≥ 0) of a rotation matrix into ``q`` (4,), for numba
    code (`matrix_to_quat_tuple`).

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        Rotation matrix.
    q : ndarray, shape (4,)
        Receives the quaternion.
    """
    q[0], q[1], q[2], q[3] = matrix_to_quat_tuple(R)


@numba.njit(cache=True)
def continuous_sign_kernel(q):
    """`continuous_sign` in place on ``q`` (N, 4), for numba code: each sample takes the
    sign that makes its dot product with the previous (corrected) one non-negative; a row
    after a NaN row keeps its sign.

    Parameters
    ----------
    q : ndarray, shape (N, 4)
        Quaternions [w, x, y, z] in time order.
    """
    for i in range(1, q.shape[0]):
        dot = (q[i, 0] * q[i - 1, 0] + q[i, 1] * q[i - 1, 1] + q[i, 2] * q[i - 1, 2]
               + q[i, 3] * q[i - 1, 3])
        if dot < 0.0:
            for c in range(4):
                q[i, c] = -q[i, c]


@numba.njit(cache=True)
def _matrix_batch(Q, out):
    for i in range(Q.shape[0]):
        out[i] = rotation_kernel(Q[i])


@numba.njit(cache=True)
def _quat_batch(R, out):
    for i in range(R.shape[0]):
        matrix_to_quat_kernel(R[i], out[i])
