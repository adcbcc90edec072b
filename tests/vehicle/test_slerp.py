"""Spherical linear interpolation of attitude quaternions (`mavsysid.estimation.readers.slerp`)."""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.rotation import interpolate_quaternions, quat_exp, quat_to_matrix


def test_slerp_halves_the_turn_and_ignores_sign_flips() -> None:
    """Between yaw 0 and 1 rad (the second stored as −q) the midpoint is yaw 0.5 rad."""
    q = quat_exp(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    q[1] *= -1.0
    mid = interpolate_quaternions(np.array([0.0, 1.0]), q, np.array([0.0, 0.5, 1.0]))
    expected = quat_to_matrix(quat_exp(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5],
                                                 [0.0, 0.0, 1.0]])))
    np.testing.assert_allclose(quat_to_matrix(mid), expected, atol=1e-12)
