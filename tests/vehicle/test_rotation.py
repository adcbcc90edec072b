"""Tests of the quaternion helpers: numpy versions and compiled kernels agree."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.rotation import (
    exp_kernel,
    log_kernel,
    matrix_to_quat,
    multiply_kernel,
    quat_exp,
    quat_log,
    quat_multiply,
    quat_to_matrix,
)


@pytest.mark.parametrize("scale", [1e-9, 1e-3, 0.5, 3.0])
def test_kernels_match_numpy_versions(scale):
    """exp/log/multiply kernels give the numpy functions' results, small angles included."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        v = scale * rng.normal(size=3) / np.sqrt(3)
        q1, q2 = quat_exp(rng.normal(size=3)), quat_exp(v)
        np.testing.assert_allclose(exp_kernel(v), quat_exp(v), atol=1e-15)
        np.testing.assert_allclose(log_kernel(q2), quat_log(q2), atol=1e-15)
        np.testing.assert_allclose(multiply_kernel(q1, q2), quat_multiply(q1, q2), atol=1e-15)


def test_exp_log_round_trip_and_matrix_conversion():
    """Log(Exp(v)) = v for angles below π, and R ↔ q conversions are inverse."""
    rng = np.random.default_rng(2)
    v = rng.normal(size=(50, 3))
    v *= (np.pi * 0.99 * rng.uniform(size=(50, 1))) / np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(quat_log(quat_exp(v)), v, atol=1e-12)
    q = quat_exp(v)
    np.testing.assert_allclose(np.abs(np.sum(matrix_to_quat(quat_to_matrix(q)) * q, axis=1)), 1.0,
                               atol=1e-12)
