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
from mavsysid.vehicle.rotation import quat_exp, quat_to_matrix

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
