"""Tests of the quaternion helpers: numpy versions, compiled kernels and tuple forms agree."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.rotation import (
    conjugate_tuple,
    continuous_sign,
    continuous_sign_kernel,
    exp_kernel,
    exp_tuple,
    interpolate_quaternions,
    log_kernel,
    log_tuple,
    matrix_to_quat,
    matrix_to_quat_tuple,
    multiply_kernel,
    multiply_tuple,
    normalized_tuple,
    quat_conjugate,
    quat_exp,
    quat_log,
    quat_multiply,
    quat_to_matrix,
    rotate_inverse_tuple,
    rotate_tuple,
    slerp_tuple,
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


def test_tuple_forms_match_the_numpy_versions_for_arrays_and_tuples():
    """The allocation-free tuple forms give the numpy results whether they are handed
    arrays or tuples; R(q) v and R(q)ᵀ v without R agree with the matrix."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        q1, q2 = quat_exp(rng.normal(size=3)), quat_exp(rng.normal(size=3))
        v = rng.normal(size=3)
        for a, b, u in ((q1, q2, v), (tuple(q1), tuple(q2), tuple(v))):
            np.testing.assert_allclose(multiply_tuple(a, b), quat_multiply(q1, q2), atol=1e-15)
            np.testing.assert_allclose(conjugate_tuple(a), quat_conjugate(q1), atol=0.0)
            np.testing.assert_allclose(exp_tuple(u), quat_exp(v), atol=1e-15)
            np.testing.assert_allclose(log_tuple(a), quat_log(q1), atol=1e-15)
            np.testing.assert_allclose(normalized_tuple(tuple(3.0 * np.asarray(a))), q1,
                                       atol=1e-15)
            np.testing.assert_allclose(rotate_tuple(a, u), quat_to_matrix(q1) @ v, atol=1e-14)
            np.testing.assert_allclose(rotate_inverse_tuple(a, u), quat_to_matrix(q1).T @ v,
                                       atol=1e-14)


def test_matrix_to_quat_is_exact_at_half_turns():
    """R → q at rotations by π about each axis and about a diagonal (trace −1, where the
    trace alone gives no scalar part) and near them, from arrays and from tuples of rows."""
    axes = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1.0, 1.0, 0], [1.0, -2.0, 3.0]])
    for axis in axes:
        for angle in (np.pi, np.pi - 1e-9, 0.5):
            v = angle * axis / np.linalg.norm(axis)
            q = quat_exp(v)
            R = quat_to_matrix(q)
            rows = tuple(tuple(r) for r in R)
            for got in (matrix_to_quat_tuple(R), matrix_to_quat_tuple(rows)):
                assert got[0] >= 0.0
                assert abs(np.dot(got, q)) == pytest.approx(1.0, abs=1e-12)


def test_slerp_tuple_matches_interpolate_quaternions():
    """The single-sample slerp is the sampled one's, sign flips between neighbours included."""
    rng = np.random.default_rng(4)
    q = quat_exp(rng.normal(size=(2, 3)))
    q[1] *= -1.0
    for s in (0.0, 0.3, 1.0):
        expected = interpolate_quaternions(np.array([0.0, 1.0]), q, np.array([s]))[0]
        np.testing.assert_allclose(slerp_tuple(q[0], q[1], s), expected, atol=1e-14)


def test_continuous_sign_flips_to_the_previous_sample_and_restarts_after_nan():
    """Each row takes the sign nearest its (corrected) predecessor; a row after a NaN row
    keeps its own sign, in the numpy form and the in-place kernel alike."""
    rng = np.random.default_rng(5)
    q = quat_exp(0.1 * np.cumsum(rng.normal(size=(40, 3)), axis=0))
    signs = np.where(rng.uniform(size=40) < 0.5, -1.0, 1.0)
    out = continuous_sign(signs[:, None] * q)
    np.testing.assert_allclose(out, signs[0] * q, atol=0.0)
    gap = signs[:, None] * q
    gap[10] = np.nan
    continuous_sign_kernel(gap)
    np.testing.assert_allclose(gap[:10], signs[0] * q[:10], atol=0.0)
    np.testing.assert_allclose(gap[11:], signs[11] * q[11:], atol=0.0)
