"""`ParameterEstimate`'s D-optimality on covariances of very different scales."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation import ParameterEstimate


def _correlation(rng: np.random.Generator, size: int) -> np.ndarray:
    """A seeded correlation matrix with strong but not degenerate correlations."""
    a = rng.normal(size=(size, 2 * size))
    cov = a @ a.T
    d = np.sqrt(np.diag(cov))
    return cov / np.outer(d, d)


#: θ's correlations in the answer of a 30 s RotorPy Crazyflie flight (`bench/rotorpy_planned.py`,
#: seed 1, planned): c_M and j_z nearly collinear, c_D left at its prior.
FLIGHT_CORRELATION = np.array([
    [1.0, 0.0, 0.1206, 0.2282, 0.3289, 0.1275],
    [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
    [0.1206, 0.0, 1.0, 0.0815, -0.547, 0.9886],
    [0.2282, 0.0, 0.0815, 1.0, 0.3288, 0.1422],
    [0.3289, 0.0, -0.547, 0.3288, 1.0, -0.5626],
    [0.1275, 0.0, 0.9886, 0.1422, -0.5626, 1.0]])


@pytest.mark.parametrize("scale", [1.0, 0.5, 2.0])
def test_d_optimality_holds_on_a_small_vehicles_scales(scale: float) -> None:
    """A Crazyflie's θ: σ from 7e-12 (c_M) to 1.6e-2 (c_D at its prior), c_M and j_z
    correlated at 0.99: the D-optimality is det(Σθ)^(1/6) to 1e-9, as from the σ and the
    correlation separately (an eigensolver on Σθ itself returns a negative eigenvalue)."""
    sigma = scale * np.array([1.28e-11, 1.58e-2, 7.06e-12, 5.41e-8, 5.43e-8, 2.77e-7])
    estimate = ParameterEstimate(np.array([2.3e-8, 0.025, 7.8e-10, 1.4e-5, 1.4e-5, 2.9e-5]),
                                 FLIGHT_CORRELATION * np.outer(sigma, sigma))
    sign, log_det = np.linalg.slogdet(FLIGHT_CORRELATION)
    assert sign > 0
    expected = np.exp((2.0 * np.sum(np.log(sigma)) + log_det) / 6.0)
    assert estimate.d_optimality == pytest.approx(expected, rel=1e-9)


def test_d_optimality_is_of_theta_alone_and_plain_on_like_scales() -> None:
    """Nuisance quantities after θ do not enter; on like scales it is det(Σθ)^(1/6)."""
    rng = np.random.default_rng(3)
    cov = _correlation(rng, 8) * 0.01
    names = ("c_T", "c_D", "c_M", "j_x", "j_y", "j_z", "bias_x", "bias_y")
    estimate = ParameterEstimate(np.ones(8), cov, names)
    assert estimate.d_optimality == pytest.approx(np.linalg.det(cov[:6, :6]) ** (1 / 6),
                                                  rel=1e-9)


def test_d_optimality_of_a_zero_variance_is_zero() -> None:
    cov = np.diag([1e-4, 0.0, 1e-4, 1e-4, 1e-4, 1e-4])
    assert ParameterEstimate(np.ones(6), cov).d_optimality == 0.0
