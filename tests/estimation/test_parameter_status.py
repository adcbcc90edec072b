"""θ from the balance coefficients, the σ widening, and the determination rule."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.balance.rows import STACKED_COEFFICIENTS
from mavsysid.estimation.balance.theta import (
    coefficients_from_theta,
    errors_in_variables_sigma,
    split_widening,
    theta_from_coefficients,
    widened_sigma,
)
from mavsysid.estimation.results import (
    MAX_RELATIVE_SIGMA,
    Z95,
    parameter_status,
)
from mavsysid.vehicle.config import load_vehicle

THETA = load_vehicle("micro_quad").theta


@pytest.mark.parametrize("theta", [THETA, THETA * [1.3, 0.7, 1.1, 0.9, 1.2, 1.4]])
def test_theta_round_trips_through_the_coefficients(theta):
    """θ → coefficients → θ is the identity, the combinations included."""
    b = coefficients_from_theta(theta)
    data = theta_from_coefficients(b, np.diag((1e-3 * np.abs(b) + 1e-12) ** 2))
    assert np.allclose(data.value, theta, rtol=1e-9)
    assert data.combinations[0] == pytest.approx(theta[2] / theta[5])
    assert np.all(np.isfinite(data.sigma)) and np.all(data.sigma > 0)


def test_delta_method_sigma_of_an_inertia_follows_its_ratio():
    """σ(j_x)/j_x equals σ(c_T/j_x)/(c_T/j_x) when c_T is exact."""
    b = coefficients_from_theta(THETA)
    k = STACKED_COEFFICIENTS.index("c_T/j_x")
    cov = np.diag((1e-6 * np.abs(b) + 1e-30) ** 2)
    cov[k, k] = (0.05 * b[k]) ** 2
    data = theta_from_coefficients(b, cov)
    assert data.sigma[3] / THETA[3] == pytest.approx(0.05, rel=1e-3)


def test_an_unexcited_coefficient_makes_what_uses_it_unknown():
    """c_M/j_z unexcited (σ = inf): c_M unknown, c_T and j_x unaffected."""
    b = coefficients_from_theta(THETA)
    cov = np.diag((0.01 * np.abs(b) + 1e-30) ** 2)
    k = STACKED_COEFFICIENTS.index("c_M/j_z")
    cov[k, k] = np.inf
    data = theta_from_coefficients(b, cov)
    assert np.isinf(data.covariance[2, 2])
    assert np.isfinite(data.sigma[[0, 3, 4]]).all()


def test_disagreeing_j_z_routes_widen_j_z_and_c_m():
    """Roll's and pitch's gyroscopic coefficients implying different j_z add σ to j_z, c_M."""
    b = coefficients_from_theta(THETA)
    cov = np.diag((1e-3 * np.abs(b) + 1e-30) ** 2)
    agree = theta_from_coefficients(b, cov)
    b2 = b.copy()
    b2[STACKED_COEFFICIENTS.index("g_x")] *= 1.5
    disagree = theta_from_coefficients(b2, cov)
    assert agree.route_sigma[5] == 0.0
    assert disagree.route_sigma[5] > 0.05 * THETA[5]
    assert disagree.route_sigma[2] > 0.0 and disagree.route_sigma[3] == 0.0


@pytest.mark.parametrize(("a", "b", "sa", "sb", "expected"), [
    (1.0, 1.1, 0.1, 0.1, 0.0),                            # within σ: nothing added
    (1.0, 2.0, 0.1, 0.1, np.sqrt((1.0 - 0.02) / 4.0)),   # beyond: half the excess
    (1.0, np.nan, 0.1, 0.1, 0.0),                        # not formed: nothing
])
def test_split_widening(a, b, sa, sb, expected):
    """σ added by two disagreeing halves is sqrt(max(0, d² − σ_a² − σ_b²)/4)."""
    assert split_widening(np.array(a), np.array(sa), np.array(b), np.array(sb)) \
        == pytest.approx(expected)


def test_errors_in_variables_sigma_reaches_the_reverse_value():
    """z₀.₉₇₅ σ_eiv is the distance to the reverse value."""
    assert errors_in_variables_sigma(np.array(1.0), np.array(1.2)) * Z95 == pytest.approx(0.2)
    assert widened_sigma([[3.0], [4.0]])[0] == pytest.approx(5.0)


@pytest.mark.parametrize(("value", "sigma", "determined"), [
    (1.0, MAX_RELATIVE_SIGMA, True), (1.0, 1.01 * MAX_RELATIVE_SIGMA, False),
    (-1.0, 0.01, False), (np.nan, 0.01, False), (1.0, np.inf, False), (0.0, 0.0, False)])
def test_determined_means_physical_with_a_narrow_widened_sigma(value, sigma, determined):
    """Determined ⇔ positive value and widened σ ≤ 12.5 % of it."""
    assert parameter_status(np.array([value]), np.array([sigma]))[0] == determined


def test_a_sensor_prior_pulls_a_traded_bias_and_theta_follows_through_their_covariance(
) -> None:
    from mavsysid.estimation.balance.theta import with_nuisance_prior
    from mavsysid.estimation.results import DataTheta

    # c_T and an accelerometer bias along the thrust traded one for one: the data alone
    # put the bias at +0.5 m/s² and c_T 5 % low, with a correlation of −0.95.
    c_t, bias = 4.58e-5, 0.5
    sigma = np.array([0.6e-6, 1e-3, 1e-8, 1e-3, 1e-3, 1e-3, 0.17])
    corr = np.eye(7)
    corr[0, 6] = corr[6, 0] = -0.95
    cov = corr * np.outer(sigma, sigma)
    value = np.array([c_t, 0.02, 7.7e-7, 0.023, 0.023, 0.046, bias])
    data = DataTheta(value, cov, np.zeros(2), np.zeros(2), np.zeros(7))
    prior_sigma = np.r_[np.full(6, 1.0), 0.1]  # θ's prior is ignored
    combined = with_nuisance_prior(data, np.zeros(7), prior_sigma)
    # The joint Gaussian's conditional: information form on the bias.
    info = np.linalg.inv(cov)
    info[6, 6] += 1.0 / 0.1**2
    expected_cov = np.linalg.inv(info)
    expected = expected_cov @ (np.linalg.inv(cov) @ value)
    assert np.allclose(combined.value, expected, rtol=1e-9, atol=0)
    assert np.allclose(combined.covariance, expected_cov, rtol=1e-6, atol=1e-30)
    assert combined.value[0] > c_t and combined.value[6] < bias
    assert np.allclose(combined.value[1:6], value[1:6])  # uncorrelated ones stay
    # Without a finite prior σ on the bias nothing changes.
    same = with_nuisance_prior(data, np.zeros(7), np.r_[np.full(6, 1.0), 0.0])
    assert same is data
