"""Tests of the plausibility check of an estimated θ (`mavsysid.estimation.checks`)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.checks import (
    PRIOR_FACTOR_MAX,
    check_plausible,
    implausibility,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle
from mavsysid.vehicle.config_checks import INERTIA_TRIANGLE_SLACK

from mavsysid.cli.main import exit_code
from mavsysid.errors import JobFailedError

PRIOR = load_vehicle("quad_x").theta
PRIOR_SIGMA = 0.5 * PRIOR


def _theta(**changes: float) -> np.ndarray:
    theta = PRIOR.copy()
    for name, value in changes.items():
        theta[PARAMETER_NAMES.index(name)] = value
    return theta


def test_prior_itself_is_plausible() -> None:
    assert implausibility(PRIOR, PRIOR_SIGMA, PRIOR, PRIOR_SIGMA) is None


def test_estimates_near_the_prior_are_plausible() -> None:
    """Seeded draws within a factor 3 of the prior (J kept a rigid body) all pass."""
    rng = np.random.default_rng(17)
    for _ in range(200):
        theta = PRIOR * np.exp(rng.uniform(-np.log(3.0), np.log(3.0), 6))
        theta[3:] = PRIOR[3:] * rng.uniform(0.8, 1.2)  # one common factor keeps J's shape
        assert implausibility(theta, 0.1 * theta, PRIOR, PRIOR_SIGMA) is None


@pytest.mark.parametrize("name", PARAMETER_NAMES)
@pytest.mark.parametrize("value", [0.0, -1e-15])
def test_non_positive_parameter_is_refused(name: str, value: float) -> None:
    theta = _theta(**{name: value})
    reason = implausibility(theta, 0.1 * np.abs(PRIOR), PRIOR, PRIOR_SIGMA)
    assert reason is not None and reason.startswith(f"{name} = ")
    assert "not positive" in reason


def test_held_zero_c_D_is_not_checked() -> None:
    """A config with c_D = 0 and prior σ 0 holds c_D at 0: the user's choice, not refused."""
    prior = _theta(c_D=0.0)
    prior_sigma = 0.5 * prior
    assert implausibility(prior, prior_sigma, prior, prior_sigma) is None
    assert implausibility(prior, prior_sigma, prior, None) is not None


@pytest.mark.parametrize("factor", [PRIOR_FACTOR_MAX * 1.01, 1.0 / (PRIOR_FACTOR_MAX * 1.01)])
def test_far_outside_prior_is_refused(factor: float) -> None:
    theta = _theta(c_M=PRIOR[2] * factor)
    reason = implausibility(theta, 0.01 * theta, PRIOR, PRIOR_SIGMA)
    assert reason is not None and reason.startswith("c_M = ")
    assert ("above" if factor > 1 else "below") + " the prior" in reason
    assert "the model does not fit this log" in reason  # σ small: not "undetermined"
    assert "prior is wrong" in reason


@pytest.mark.parametrize("factor", [PRIOR_FACTOR_MAX * 0.99, 1.0 / (PRIOR_FACTOR_MAX * 0.99)])
def test_just_inside_prior_factor_passes(factor: float) -> None:
    theta = _theta(c_T=PRIOR[0] * factor)
    assert implausibility(theta, 0.01 * theta, PRIOR, PRIOR_SIGMA) is None


def test_triangle_inequality_uses_the_config_slack() -> None:
    j_x, j_y = PRIOR[3], PRIOR[4]
    inside = _theta(j_z=(j_x + j_y) * (1.0 + INERTIA_TRIANGLE_SLACK) * 0.999)
    outside = _theta(j_z=(j_x + j_y) * (1.0 + INERTIA_TRIANGLE_SLACK) * 1.001)
    assert implausibility(inside, None, PRIOR) is None
    reason = implausibility(outside, None, PRIOR)
    assert reason is not None and "triangle inequality" in reason and "j_x + j_y" in reason


def test_non_finite_value_or_sigma_is_refused() -> None:
    assert implausibility(_theta(j_y=np.nan), None, PRIOR) is not None
    sigma = 0.1 * PRIOR
    sigma[1] = np.inf
    assert implausibility(PRIOR, sigma, PRIOR) is not None


def test_refusal_is_one_line_naming_file_parameter_and_numbers() -> None:
    theta = _theta(c_M=1.29e-9)
    sigma = 0.1 * PRIOR
    sigma[2] = 6.6e-9
    with pytest.raises(JobFailedError) as info:
        check_plausible("flight.ulg", theta, sigma, PRIOR, PRIOR_SIGMA)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("flight.ulg: c_M = 1.29e-09 ± 6.6e-09 N·m/(rad/s)²")
    assert f"below the prior {PRIOR[2]:.3g}" in message
    assert "the log does not determine it" in message  # σ larger than the value
    assert exit_code(info.value) == 3


def test_vanishing_parameters_of_rotor_drag_linear() -> None:
    """Only c_D may vanish, and only with rotor drag linear in rotor speed in the model."""
    assert not vanishing_parameters([]).any()
    assert not vanishing_parameters(["wind", "motor_lag"]).any()
    mask = vanishing_parameters(["wind", "rotor_drag_linear"])
    assert list(np.flatnonzero(mask)) == [PARAMETER_NAMES.index("c_D")]


@pytest.mark.parametrize("sigma_factor", [0.3, 1.0, 1.9])
def test_c_d_near_zero_is_accepted_with_linear_rotor_drag(sigma_factor: float) -> None:
    """c_D ≤ 0 within 2 σ of 0 (−2.51e-05 ± 0.00015 s/m, as a diverged filter gave) is refused by
    default and accepted when the model lets c_D vanish."""
    sigma = PRIOR_SIGMA.copy()
    i = PARAMETER_NAMES.index("c_D")
    sigma[i] = 1.5e-4
    theta = _theta(c_D=-sigma_factor * sigma[i])
    may_vanish = vanishing_parameters(["rotor_drag_linear"])
    assert "is not positive" in implausibility(theta, sigma, PRIOR, PRIOR_SIGMA)
    assert implausibility(theta, sigma, PRIOR, PRIOR_SIGMA, may_vanish) is None
    check_plausible("x.csv", theta, sigma, PRIOR, PRIOR_SIGMA, may_vanish=may_vanish)


def test_vanishing_c_d_far_below_zero_or_without_sigma_is_refused() -> None:
    """More than 2 σ below 0, or no σ to judge by, is still refused; so is any other
    parameter at 0."""
    sigma = PRIOR_SIGMA.copy()
    i = PARAMETER_NAMES.index("c_D")
    sigma[i] = 1.5e-4
    may_vanish = vanishing_parameters(["rotor_drag_linear"])
    assert "c_D" in implausibility(_theta(c_D=-2.1 * sigma[i]), sigma, PRIOR, PRIOR_SIGMA,
                                   may_vanish)
    assert "c_D" in implausibility(_theta(c_D=-1e-6), None, PRIOR, None, may_vanish)
    assert "c_M" in implausibility(_theta(c_M=-1e-12), sigma, PRIOR, PRIOR_SIGMA, may_vanish)


def test_vanishing_c_d_may_be_far_below_its_prior_but_not_above() -> None:
    """A small positive c_D far below the prior passes when it may vanish; far above not."""
    i = PARAMETER_NAMES.index("c_D")
    may_vanish = vanishing_parameters(["rotor_drag_linear"])
    small = _theta(c_D=PRIOR[i] / (10 * PRIOR_FACTOR_MAX))
    assert "below the prior" in implausibility(small, PRIOR_SIGMA, PRIOR, PRIOR_SIGMA)
    assert implausibility(small, PRIOR_SIGMA, PRIOR, PRIOR_SIGMA, may_vanish) is None
    large = _theta(c_D=PRIOR[i] * 10 * PRIOR_FACTOR_MAX)
    assert "above the prior" in implausibility(large, PRIOR_SIGMA, PRIOR, PRIOR_SIGMA,
                                               may_vanish)


@pytest.mark.parametrize(("fraction", "accepted"), [(0.5, True), (0.99, True), (1.5, False)])
def test_c_d_below_zero_is_bounded_by_the_linear_drag_it_corrects(fraction, accepted):
    """Beside rotor_drag_linear (k), c_D ≥ −k/(c_T n_max) keeps k n + c_T c_D n² a drag up
    to the top rotor speed: accepted however small its σ; below that, refused."""
    from mavsysid.vehicle.model_effects import RotorDragLinear

    config = load_vehicle("quad_x")
    k = 2e-4
    floor = vanishing_floor([RotorDragLinear(k=k, k_z=1e-4)], PRIOR[0],
                            config.limits.rotor_speed_max)
    bound = -k / (PRIOR[0] * config.limits.rotor_speed_max)
    assert floor[PARAMETER_NAMES.index("c_D")] == pytest.approx(bound)
    assert np.count_nonzero(floor) == 1
    theta = _theta(c_D=fraction * bound)
    sigma = PRIOR_SIGMA.copy()
    sigma[PARAMETER_NAMES.index("c_D")] = 1e-6
    may_vanish = vanishing_parameters(["rotor_drag_linear"])
    reason = implausibility(theta, sigma, PRIOR, PRIOR_SIGMA, may_vanish, floor)
    assert (reason is None) is accepted
    assert "is not positive" in implausibility(theta, sigma, PRIOR, PRIOR_SIGMA, may_vanish)
