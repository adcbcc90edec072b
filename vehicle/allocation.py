"""Rotor allocation: rotor speeds squared ↔ collective thrust and body torques.

Paper Eq. (allocation): [J ω̇ + ω × J ω ; m |a - g|] = A n², here ordered
``[T, τ_x, τ_y, τ_z]`` (collective thrust first). Rotor drag is neglected, as in the
paper: thrust acts along z_B at r_i, so the torque of rotor i is r_i × (0, 0, c_T n_i²)
= c_T n_i² (y_i, -x_i, 0) plus its reaction moment -ε_i c_M n_i² about z_B.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from mavsysid.vehicle.config_types import VehicleConfig

__all__ = ["allocation_matrix", "allocation_pinv", "rotor_speeds_squared"]


def allocation_matrix(config: VehicleConfig, theta: np.ndarray | None = None) -> np.ndarray:
    """Allocation matrix A, shape (4, k): ``[T, τ_x, τ_y, τ_z] = A n²``.

    Parameters
    ----------
    config : VehicleConfig
        Rotor geometry and directions.
    theta : ndarray, shape (6,), optional
        Parameters [c_T, c_D, c_M, j_x, j_y, j_z]; the config's nominal θ by default.

    Returns
    -------
    ndarray, shape (4, k)
        Rows: collective thrust (N), roll, pitch and yaw torque (N·m), per n² ((rad/s)²).
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)
    return _matrix(config.rotor_positions, config.rotor_directions, theta[0], theta[2])


def _matrix(r: np.ndarray, eps: np.ndarray, c_T: float, c_M: float) -> np.ndarray:
    return np.vstack([np.full(r.shape[0], c_T), c_T * r[:, 1], -c_T * r[:, 0], -eps * c_M])


def allocation_pinv(config: VehicleConfig, theta: np.ndarray | None = None) -> np.ndarray:
    """Minimum-norm right inverse A⁺ of the allocation matrix, shape (k, 4).

    For 4 rotors this is the exact inverse; for more it gives the n² of least norm.

    Parameters
    ----------
    config : VehicleConfig
        Rotor layout.
    theta : ndarray, shape (6,), optional
        θ in SI (default: the nominal).
    """
    theta = config.theta if theta is None else np.asarray(theta, dtype=float)
    # The SVD costs more than the flatness of a whole segment, and θ rarely changes.
    return _cached_pinv(config.rotor_positions.tobytes(), config.rotor_directions.tobytes(),
                        float(theta[0]), float(theta[2])).copy()


@lru_cache(maxsize=64)
def _cached_pinv(positions: bytes, directions: bytes, c_T: float, c_M: float) -> np.ndarray:
    r = np.frombuffer(positions).reshape(-1, 3)
    return np.linalg.pinv(_matrix(r, np.frombuffer(directions), c_T, c_M))


def rotor_speeds_squared(
    wrench: np.ndarray, config: VehicleConfig, theta: np.ndarray | None = None
) -> np.ndarray:
    """n² that produce a thrust and torque, shape (..., 4) → (..., k).

    Parameters
    ----------
    wrench : ndarray, shape (..., 4)
        ``[T, τ_x, τ_y, τ_z]`` in N and N·m.
    config : VehicleConfig
        Rotor layout.
    theta : ndarray, shape (6,), optional
        θ in SI (default: the nominal).

    Returns
    -------
    ndarray, shape (..., k)
        Rotor speeds squared, (rad/s)². Entries may be negative or exceed the limit when
        the wrench is not achievable; callers check feasibility.
    """
    return np.asarray(wrench, dtype=float) @ allocation_pinv(config, theta).T
