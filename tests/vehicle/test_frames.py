"""Tests of the ENU/FLU ↔ NED/FRD conversions (vehicle/frames.py)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.frames import (
    enu_to_ned,
    euler_ned_to_quaternion,
    flu_to_frd,
    frd_to_flu,
    ned_to_enu,
    quaternion_enu_to_ned,
    quaternion_ned_to_enu,
    yaw_enu_to_ned,
    yaw_ned_to_enu,
)
from mavsysid.vehicle.rotation import quat_exp, quat_normalize, quat_to_matrix

SWAP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # ENU ↔ NED
FLIP = np.diag([1.0, -1.0, -1.0])  # FLU ↔ FRD


@pytest.mark.parametrize(("forward", "inverse"), [(enu_to_ned, ned_to_enu),
                                                  (flu_to_frd, frd_to_flu),
                                                  (quaternion_enu_to_ned, quaternion_ned_to_enu),
                                                  (yaw_enu_to_ned, yaw_ned_to_enu)])
def test_conversions_invert_each_other(forward, inverse):
    """Each conversion followed by its inverse returns the input, for batches of inputs."""
    rng = np.random.default_rng(3)
    size = 4 if forward in (quaternion_enu_to_ned,) else 3
    x = rng.uniform(-3.0, 3.0, (7, size)) if forward is not yaw_enu_to_ned \
        else rng.uniform(-np.pi, np.pi, 7)
    np.testing.assert_allclose(inverse(forward(x)), x, atol=1e-12)


def test_quaternion_to_ned_rotates_as_the_swapped_matrices():
    """q_ned_frd rotates as T R_enu_flu B: the same physical attitude in NED/FRD axes."""
    rng = np.random.default_rng(4)
    q = quat_exp(rng.normal(size=(20, 3)))
    expected = SWAP @ quat_to_matrix(q) @ FLIP
    np.testing.assert_allclose(quat_to_matrix(quaternion_enu_to_ned(q)), expected, atol=1e-12)


def test_euler_angles_match_a_heading_rotation():
    """Pure yaw ψ about NED down gives the NED heading ψ; scalars and arrays both work."""
    q = euler_ned_to_quaternion(0.0, 0.0, 0.3)
    np.testing.assert_allclose(q, [np.cos(0.15), 0.0, 0.0, np.sin(0.15)], atol=1e-15)
    batch = euler_ned_to_quaternion(np.zeros(2), np.zeros(2), np.array([0.3, -0.3]))
    assert batch.shape == (2, 4)


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
