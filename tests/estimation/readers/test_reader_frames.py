"""NED/FRD → ENU/FLU conversions and quaternion interpolation of the readers."""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.readers.frames import interpolate_quaternions
from mavsysid.vehicle.frames import euler_ned_to_quaternion, ned_to_enu, quaternion_ned_to_enu
from mavsysid.vehicle.rotation import quat_exp, quat_normalize, quat_to_matrix

SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # ENU ↔ NED
FLIP = np.diag([1.0, -1.0, -1.0])  # FLU ↔ FRD


def test_quaternion_conversion_matches_rotation_matrices() -> None:
    """q_enu_flu rotates as T R_ned_frd B for random attitudes."""
    rng = np.random.default_rng(1)
    q_ned = quat_normalize(rng.normal(size=(50, 4)))
    q_enu = quaternion_ned_to_enu(q_ned)
    np.testing.assert_allclose(quat_to_matrix(q_enu), SWAP @ quat_to_matrix(q_ned) @ FLIP,
                               atol=1e-12)


def test_position_conversion_swaps_and_flips() -> None:
    """(north, east, down) becomes (east, north, up)."""
    np.testing.assert_array_equal(ned_to_enu(np.array([[1.0, 2.0, 3.0]])), [[2.0, 1.0, -3.0]])


def test_euler_angles_compose_yaw_pitch_roll() -> None:
    """The Euler quaternion rotates as Rz(yaw) Ry(pitch) Rx(roll)."""
    rng = np.random.default_rng(2)
    roll, pitch, yaw = rng.uniform(-1.5, 1.5, (3, 20))
    expected = []
    for r, p, y in zip(roll, pitch, yaw, strict=True):
        rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
        ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
        rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
        expected.append(rz @ ry @ rx)
    q = euler_ned_to_quaternion(roll, pitch, yaw)
    np.testing.assert_allclose(quat_to_matrix(q), np.array(expected), atol=1e-12)


def test_slerp_halves_the_turn_and_ignores_sign_flips() -> None:
    """Between yaw 0 and 1 rad (the second stored as −q) the midpoint is yaw 0.5 rad."""
    q = quat_exp(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    q[1] *= -1.0
    mid = interpolate_quaternions(np.array([0.0, 1.0]), q, np.array([0.0, 0.5, 1.0]))
    expected = quat_to_matrix(quat_exp(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5],
                                                 [0.0, 0.0, 1.0]])))
    np.testing.assert_allclose(quat_to_matrix(mid), expected, atol=1e-12)
