"""The per-parameter answer: the balance checked by the filter, statuses and mismatches."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from mavsysid.estimation.answer import (
    answer_parameters,
    balance_only_result,
    with_curve_uncertainty,
)
from mavsysid.estimation.results import (
    AT_BOUND,
    DETERMINED,
    NOT_DETERMINED,
    DataTheta,
    EstimationResult,
    FitChoices,
    ParameterEstimate,
    WrenchBalanceResult,
)
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import JobFailedError

THETA = load_vehicle("micro_quad").theta
PRIOR = ParameterEstimate(THETA * 1.3, np.diag((0.5 * THETA * 1.3) ** 2))


def _balance(value: np.ndarray, relative_sigma: np.ndarray) -> WrenchBalanceResult:
    sigma = np.abs(value) * relative_sigma
    determined = (value > 0) & (relative_sigma <= 0.125)
    estimate = ParameterEstimate(np.where(determined, value, PRIOR.value),
                                 np.diag(np.where(determined, sigma, PRIOR.sigma) ** 2))
    parts = np.zeros((6, 6))
    parts[0] = sigma
    data = DataTheta(value, np.diag(sigma**2), np.zeros(2), np.zeros(2), np.zeros(6))
    return WrenchBalanceResult(estimate, determined, data, parts, np.zeros(2), PRIOR,
                               FitChoices(0.06, None, None, 0.0, 0.0), 0.001, None, 100)


def _filter(value: np.ndarray, relative_sigma: float) -> EstimationResult:
    balance = _balance(THETA, np.full(6, 0.01))
    result = balance_only_result(balance, PRIOR, (1e-3, 1e-3), "motion_capture", None, ())
    est = ParameterEstimate(value, np.diag((relative_sigma * value) ** 2))
    return dataclasses.replace(result, filtered=est, refined=est)


def _answer(filt, balance, prior):
    answer = answer_parameters(filt, balance, prior)
    return answer.estimate, answer.status, answer.source, answer.mismatch


def _correlated_filter(value: np.ndarray, relative_sigma: float, lean: float
                       ) -> EstimationResult:
    """A filter whose c_M and j_z lean on its c_D with correlation ``lean``."""
    filt = _filter(value, relative_sigma)
    sigma = relative_sigma * value
    corr = np.eye(6)
    for i, j in ((1, 2), (1, 5), (2, 5)):
        corr[i, j] = corr[j, i] = lean
    est = ParameterEstimate(value, corr * np.outer(sigma, sigma))
    return dataclasses.replace(filt, filtered=est, refined=est)


def test_agreeing_estimates_give_the_filters_value():
    """Both determine θ and agree: the filter's (more precise) value and σ, no mismatch."""
    balance = _balance(THETA * 1.01, np.full(6, 0.02))
    filt = _filter(THETA * 0.999, 0.005)
    estimate, status, source, mismatch = _answer(filt, balance, PRIOR)
    np.testing.assert_allclose(estimate.value, THETA * 0.999)
    assert status == (DETERMINED,) * 6 and source == ("filter",) * 6 and mismatch == ()


def test_disagreement_keeps_the_balance_and_reports_a_mismatch():
    """The filter 30 % off on j_x, far beyond both σ: the balance's j_x stands, named."""
    balance = _balance(THETA, np.full(6, 0.02))
    filt = _filter(THETA * np.array([1, 1, 1, 1.3, 1, 1]), 0.005)
    estimate, status, source, mismatch = _answer(filt, balance, PRIOR)
    assert source[3] == "balance" and estimate.value[3] == pytest.approx(THETA[3])
    assert status[3] == DETERMINED
    assert len(mismatch) == 1 and mismatch[0].startswith("j_x:")


def test_undetermined_parameters_keep_the_prior():
    """Neither determines c_M, j_z: prior value and σ, status 'not determined by this flight'."""
    rel = np.array([0.01, 0.05, 0.6, 0.05, 0.05, 0.6])
    estimate, status, source, _ = _answer(None, _balance(THETA, rel), PRIOR)
    for j in (2, 5):
        assert status[j] == NOT_DETERMINED and source[j] == "prior"
        assert estimate.value[j] == PRIOR.value[j] and estimate.sigma[j] == PRIOR.sigma[j]
    assert status[0] == DETERMINED and source[0] == "balance"


def test_drag_within_noise_of_zero_is_at_the_bound():
    """c_D's data value within 2 σ of 0 (σ below the prior's): 'at the bound', not refused."""
    value = THETA.copy()
    value[1] = -0.2 * PRIOR.sigma[1]
    rel = np.full(6, 0.02)
    rel[1] = 0.5  # σ = 0.1 × the prior's σ: informative, and 0 is within 2 σ
    estimate, status, source, _ = _answer(None, _balance(value, rel), PRIOR)
    assert status[1] == AT_BOUND and source[1] == "balance"
    assert estimate.value[1] == 0.0 and estimate.sigma[1] == pytest.approx(abs(value[1]) * 0.5)


def test_a_filter_that_determines_what_the_balance_does_not_answers_for_it():
    """The balance leaves j_z to the prior; a filter that determines it gives its value."""
    rel = np.array([0.01, 0.05, 0.05, 0.05, 0.05, 0.6])
    filt = _filter(THETA * 1.02, 0.01)
    estimate, status, source, _ = _answer(filt, _balance(THETA, rel), PRIOR)
    assert source[5] == "filter" and status[5] == DETERMINED
    assert estimate.value[5] == pytest.approx(THETA[5] * 1.02)


def test_nothing_to_answer_from_is_refused():
    """No filter and no balance: refused, not an answer made of the prior."""
    with pytest.raises(JobFailedError):
        answer_parameters(None, None, PRIOR)


def test_filter_outside_the_difference_sigma_gives_way_though_within_the_combined():
    """Filter σ 5 %, balance σ 6 %, 8 % apart: within 1.96 combined σ (7.8 %) but beyond
    1.96 σ of their difference (σ_b² − σ_f²)^½ = 3.3 %: the balance answers, named."""
    balance = _balance(THETA, np.full(6, 0.06))
    filt = _filter(THETA * np.array([1, 1, 1, 1.08, 1, 1]), 0.05 / 1.08)
    estimate, _, source, mismatch = _answer(filt, balance, PRIOR)
    assert source[3] == "balance" and estimate.value[3] == pytest.approx(THETA[3])
    assert [m.split(":")[0] for m in mismatch] == ["j_x"]
    assert source[4] == "filter"


def test_a_less_precise_filter_is_tested_as_an_independent_estimate():
    """The filter's σ (5 %) above the balance's (2 %): 8 % apart is within 1.96 √(σ_f² +
    σ_b²) = 10.6 %, and its wider interval stands; 12 % apart is not, and the balance
    answers."""
    balance = _balance(THETA, np.full(6, 0.02))
    filt = _filter(THETA * np.array([1.08, 1, 1, 1.12, 1, 1]), 0.05)
    filt = dataclasses.replace(filt, refined=ParameterEstimate(
        filt.refined.value, np.diag((0.05 * THETA) ** 2)))
    estimate, _, source, mismatch = _answer(filt, balance, PRIOR)
    assert source[0] == "filter" and estimate.value[0] == pytest.approx(THETA[0] * 1.08)
    assert source[3] == "balance" and estimate.value[3] == pytest.approx(THETA[3])
    assert [m.split(":")[0] for m in mismatch] == ["j_x"]


def test_a_filter_contradicted_by_an_undetermined_balance_is_not_determined():
    """The filter 60 % high on j_x; the balance's j_x (σ 15 %, not determined) far from it:
    j_x is not determined (the prior), not the filter's value."""
    rel = np.array([0.01, 0.05, 0.05, 0.15, 0.05, 0.05])
    filt = _filter(THETA * np.array([1, 1, 1, 1.6, 1, 1]), 0.1 / 1.6)
    estimate, status, source, mismatch = _answer(filt, _balance(THETA, rel), PRIOR)
    assert status[3] == NOT_DETERMINED and source[3] == "prior"
    assert estimate.value[3] == PRIOR.value[3]
    assert [m.split(":")[0] for m in mismatch] == ["j_x"]


def test_quantities_leaning_on_a_rejected_one_follow_its_answer():
    """c_D, c_M and j_z all 28 % low in the filter, σ 3 %, correlated 0.98 (the yaw ratio
    determined, its scale from c_D); the balance determines c_D at the truth and
    rejects the filter's: c_M and j_z follow, back near the truth, and say so."""
    scale = np.array([1, 0.72, 0.72, 1, 1, 0.72])
    rel = np.array([0.01, 0.05, 0.5, 0.02, 0.02, 0.5])
    answer = answer_parameters(_correlated_filter(THETA * scale, 0.03, 0.98),
                               _balance(THETA, rel), PRIOR)
    assert answer.source[1] == "balance" and [m.split(":")[0] for m in answer.mismatch] == ["c_D"]
    error = (answer.estimate.value - THETA) / answer.estimate.sigma
    assert answer.status[2] == answer.status[5] == DETERMINED
    assert np.all(np.abs(error[[2, 5]]) < 2.0)
    assert [phrase.split(" ")[0] for phrase in answer.leaning] == ["c_M", "j_z"]


def test_leaning_quantities_are_not_determined_where_the_rejected_one_is_not():
    """As above, but the balance does not determine c_D (60 % high, σ 20 %) and rejects
    the filter's: c_M and j_z lose the scale the filter's c_D gave them and are not
    determined, not left 28 % off at 3 %."""
    scale = np.array([1, 0.72, 0.72, 1, 1, 0.72])
    rel = np.array([0.01, 0.2, 0.5, 0.02, 0.02, 0.5])
    answer = answer_parameters(_correlated_filter(THETA * scale, 0.03, 0.98),
                               _balance(THETA * np.array([1, 1.6, 1, 1, 1, 1]), rel), PRIOR)
    assert [m.split(":")[0] for m in answer.mismatch] == ["c_D"]
    assert [answer.status[i] for i in (1, 2, 5)] == [NOT_DETERMINED] * 3
    assert answer.source[0] == "filter" and answer.status[0] == DETERMINED


def test_uncorrelated_quantities_keep_the_filters_value():
    """The same rejection with no correlation: the filter's c_M and j_z stand as they are."""
    scale = np.array([1, 0.72, 1.01, 1, 1, 0.99])
    rel = np.array([0.01, 0.05, 0.5, 0.02, 0.02, 0.5])
    filt = _correlated_filter(THETA * scale, 0.03, 0.0)
    answer = answer_parameters(filt, _balance(THETA, rel), PRIOR)
    assert answer.source[2] == answer.source[5] == "filter" and answer.leaning == ()
    np.testing.assert_allclose(answer.estimate.value[[2, 5]], (THETA * scale)[[2, 5]])


def test_a_refused_filter_still_keeps_c_d_off_its_bound():
    """The balance puts c_D within 2 σ of 0; a filter refused for contradicting it (c_D at
    the truth, σ 0.5 %) gives no value, but c_D is then not determined, not "at the
    bound" with the balance's σ; without that filter it is at the bound."""
    rel = np.array([0.01, 1.0, 0.05, 0.05, 0.05, 0.05])
    balance = _balance(THETA * np.array([1, 0.01, 1, 1, 1, 1]), rel)
    refused = _filter(THETA, 0.005)
    answer = answer_parameters(None, balance, PRIOR, refused_filter=refused)
    assert answer.status[1] == NOT_DETERMINED and answer.source[1] == "prior"
    assert [m.split(":")[0] for m in answer.mismatch] == ["c_D"]
    assert answer_parameters(None, balance, PRIOR).status[1] == AT_BOUND


def test_slow_rotor_speeds_leave_the_torque_quantities_to_the_balance():
    """Rotor speeds below 20 Hz: the filter's c_M and J (here 40 % off, σ 3 %) are not
    taken where the balance does not determine them; its c_T and c_D still are."""
    rel = np.array([0.01, 0.05, 0.5, 0.5, 0.5, 0.5])
    filt = _filter(THETA * np.array([1, 1, 1.4, 1.4, 1.4, 1.4]), 0.03)
    answer = answer_parameters(filt, _balance(THETA, rel), PRIOR, slow_inputs=True)
    assert [answer.status[i] for i in (2, 3, 4, 5)] == [NOT_DETERMINED] * 4
    assert answer.source[:2] == ("filter", "filter")
    assert answer_parameters(filt, _balance(THETA, rel), PRIOR).source[3] == "filter"


def test_a_filter_c_d_it_does_not_determine_still_contradicts_the_bound():
    """The balance puts c_D within 2 σ of 0; the filter's c_D, at the truth with σ 16 %
    (not determined), lies 6 σ of their difference away: not at the bound."""
    rel = np.array([0.01, 1.0, 0.05, 0.05, 0.05, 0.05])
    balance = _balance(THETA * np.array([1, 0.05, 1, 1, 1, 1]), rel)
    answer = answer_parameters(_filter(THETA, 0.16), balance, PRIOR)
    assert answer.status[1] == NOT_DETERMINED
    assert answer_parameters(_filter(THETA * np.array([1, 0.05, 1, 1, 1, 1]), 0.16),
                             balance, PRIOR).status[1] == AT_BOUND


def test_the_motor_curves_uncertainty_widens_c_t_and_c_m_together_and_nothing_else():
    """Rotor speeds through a curve known to 5 %: c_T (1 %) and c_M (4 %) gain 10 % each,
    fully correlated; c_D and J keep their σ."""
    rel = np.array([0.01, 0.05, 0.04, 0.05, 0.05, 0.05])
    answer = answer_parameters(None, _balance(THETA, rel), PRIOR)
    widened, notes = with_curve_uncertainty(answer, 0.05, PRIOR)
    sigma = widened.estimate.sigma
    np.testing.assert_allclose(sigma[[0, 2]] / THETA[[0, 2]],
                               np.sqrt(rel[[0, 2]] ** 2 + 0.1**2), rtol=1e-9)
    np.testing.assert_allclose(sigma[[1, 3, 4, 5]], answer.estimate.sigma[[1, 3, 4, 5]])
    corr = widened.estimate.covariance[0, 2] / (sigma[0] * sigma[2])
    assert corr > 0.9
    assert widened.status == answer.status and len(notes) == 1
    assert with_curve_uncertainty(answer, 0.0, PRIOR) == (answer, [])


def test_a_quantity_the_curve_widens_beyond_the_rule_is_no_longer_determined():
    """c_M at 9 % from the data, with a curve known to 5 %: 13.5 % > 12.5 %, the prior's."""
    rel = np.array([0.01, 0.05, 0.09, 0.05, 0.05, 0.05])
    answer = answer_parameters(None, _balance(THETA, rel), PRIOR)
    widened, notes = with_curve_uncertainty(answer, 0.05, PRIOR)
    assert widened.status[2] == NOT_DETERMINED and widened.source[2] == "prior"
    assert widened.estimate.value[2] == PRIOR.value[2]
    assert widened.status[0] == DETERMINED
    assert "c_M then not determined" in notes[0]
