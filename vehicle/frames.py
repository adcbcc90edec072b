"""ENU/FLU ↔ NED/FRD, for the MAVLink link and for flight logs (docs/architecture.md conventions).

mavsysid works in world ENU and body FLU; MAVLink, ArduPilot and PX4 (and so their logs)
use world NED and body FRD. Every conversion, in `flight/` at the link and in
`estimation/readers/` at the log boundary, goes through this module.

    x_ned = y_enu,  y_ned = x_enu,  z_ned = −z_enu,
    yaw_ned = π/2 − yaw_enu,  yaw_rate_ned = −yaw_rate_enu,
    (p, q, r)_FRD = (p, −q, −r)_FLU,
    q_enu_flu = √½ (w + z, x + y, x − y, w − z)  for q_ned_frd = (w, x, y, z).

All functions accept arrays whose last axis is the vector (3) or quaternion (4), so
whole logs convert in one call. Quaternions are Hamilton, scalar first, body → world.
"""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.rotation import wrap_angle

__all__ = [
    "enu_to_ned",
    "euler_ned_to_quaternion",
    "flu_to_frd",
    "frd_to_flu",
    "ned_to_enu",
    "quaternion_enu_to_ned",
    "quaternion_ned_to_enu",
    "yaw_enu_to_ned",
    "yaw_ned_to_enu",
    "yaw_rate_enu_to_ned",
    "yaw_rate_ned_to_enu",
]

_SQRT_HALF = np.sqrt(0.5)


def enu_to_ned(v: np.ndarray) -> np.ndarray:
    """World vector(s) ENU → NED (positions, velocities, accelerations), shape (..., 3).

    Parameters
    ----------
    v : ndarray, shape (..., 3)
        World vectors, ENU.
    """
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def ned_to_enu(v: np.ndarray) -> np.ndarray:
    """World vector(s) NED → ENU, shape (..., 3). The map is its own inverse.

    Parameters
    ----------
    v : ndarray, shape (..., 3)
        World vectors, NED.
    """
    return enu_to_ned(v)


def flu_to_frd(v: np.ndarray) -> np.ndarray:
    """Body vector(s) FLU → FRD (body rates, body velocities), shape (..., 3).

    Parameters
    ----------
    v : ndarray, shape (..., 3)
        Body vectors, FLU.
    """
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], axis=-1)


def frd_to_flu(v: np.ndarray) -> np.ndarray:
    """Body vector(s) FRD → FLU, shape (..., 3). The map is its own inverse.

    Parameters
    ----------
    v : ndarray, shape (..., 3)
        Body vectors, FRD.
    """
    return flu_to_frd(v)


def yaw_enu_to_ned(yaw: np.ndarray | float) -> np.ndarray | float:
    """Heading ENU (from east, counter-clockwise) → NED (from north, clockwise), rad.

    Parameters
    ----------
    yaw : float or ndarray
        Heading ENU, rad.
    """
    return wrap_angle(0.5 * np.pi - np.asarray(yaw, dtype=float))


def yaw_ned_to_enu(yaw: np.ndarray | float) -> np.ndarray | float:
    """Heading NED → ENU, rad (the same map: π/2 − ψ).

    Parameters
    ----------
    yaw : float or ndarray
        Heading NED, rad.
    """
    return yaw_enu_to_ned(yaw)


def yaw_rate_enu_to_ned(rate: np.ndarray | float) -> np.ndarray | float:
    """Yaw rate ENU → NED, rad/s.

    Parameters
    ----------
    rate : float or ndarray
        Yaw rate ENU, rad/s.
    """
    return -np.asarray(rate, dtype=float)


def yaw_rate_ned_to_enu(rate: np.ndarray | float) -> np.ndarray | float:
    """Yaw rate NED → ENU, rad/s.

    Parameters
    ----------
    rate : float or ndarray
        Yaw rate NED, rad/s.
    """
    return -np.asarray(rate, dtype=float)


def quaternion_ned_to_enu(q: np.ndarray) -> np.ndarray:
    """Attitude q_ned_frd → q_enu_flu, both [w, x, y, z], shape (..., 4).

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        q_ned_frd [w, x, y, z].
    """
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return _SQRT_HALF * np.stack([w + z, x + y, x - y, w - z], axis=-1)


def quaternion_enu_to_ned(q: np.ndarray) -> np.ndarray:
    """Attitude q_enu_flu → q_ned_frd, both [w, x, y, z], shape (..., 4).

    The inverse of `quaternion_ned_to_enu`: w = (a + d)/√2, x = (b + c)/√2,
    y = (b − c)/√2, z = (a − d)/√2 for q_enu_flu = (a, b, c, d).

    Parameters
    ----------
    q : ndarray, shape (..., 4)
        q_enu_flu [w, x, y, z].
    """
    q = np.asarray(q, dtype=float)
    a, b, c, d = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return _SQRT_HALF * np.stack([a + d, b + c, b - c, a - d], axis=-1)


def euler_ned_to_quaternion(roll: np.ndarray | float, pitch: np.ndarray | float,
                            yaw: np.ndarray | float) -> np.ndarray:
    """Aerospace (Z-Y-X) Euler angles, rad, to NED/FRD quaternions [w, x, y, z].

    q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll), the convention of MAVLink ATTITUDE and of
    ArduPilot's ATT and VISP log messages. Angles of shape (...) give shape (..., 4).

    Parameters
    ----------
    roll, pitch, yaw : float or ndarray
        Euler angles, rad.
    """
    cr, sr = np.cos(0.5 * np.asarray(roll, float)), np.sin(0.5 * np.asarray(roll, float))
    cp, sp = np.cos(0.5 * np.asarray(pitch, float)), np.sin(0.5 * np.asarray(pitch, float))
    cy, sy = np.cos(0.5 * np.asarray(yaw, float)), np.sin(0.5 * np.asarray(yaw, float))
    return np.stack([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ], axis=-1)
