"""answer."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from mavsysid.estimation.filter.guard import AGREEMENT_TOLERANCE
from mavsysid.estimation.results import (
    AT_BOUND,
    DETERMINED,
    MAX_RELATIVE_SIGMA,
    NOT_DETERMINED,
    Z95,
    EstimationHistory,
    EstimationResult,
    ParameterEstimate,
    WrenchBalanceResult,
)
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS
from mavsysid.vehicle.linearization import MEAS_DIM

from mavsysid.errors import JobFailedError

__all__ = ["AGREEMENT_SIGMAS", "BOUND_SIGMAS", "answer_parameters", "balance_only_result",
           "with_answer"]


#: Filter and balance disagree beyond this many σ of their difference (and the relative
#: tolerance): the Hausman test at the 5 % level.
AGREEMENT_SIGMAS = Z95
#: A data value within this many σ of 0 puts c_D at its bound.
BOUND_SIGMAS = 2.0
_C_D = PARAMETER_NAMES.index("c_D")


def _filter_determines(estimate: ParameterEstimate) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return (estimate.value > 0.0) & (estimate.sigma <= MAX_RELATIVE_SIGMA * estimate.value)


def _balance_data(balance: WrenchBalanceResult | None) -> tuple[np.ndarray, np.ndarray]:
    """The balance's data value and σ per parameter; σ inf where it has none."""
    n = len(PARAMETER_NAMES)
    if balance is None:
        return np.full(n, np.nan), np.full(n, np.inf)
    value = np.asarray(balance.data.value, float)
    with np.errstate(over="ignore", invalid="ignore"):  # a σ part of 1e200: inf, not determined
        sigma = np.sqrt(np.sum(balance.sigma_parts**2, axis=0))
    ok = np.isfinite(value) & np.isfinite(sigma) & (sigma > 0.0)
    return value, np.where(ok, sigma, np.inf)


def _filter_stands(fv: float, fs: float, bv: float, bs: float, tolerance: float
                   ) -> tuple[bool, float | None]:
    """Whether the filter's value stands against the balance's (module docstring), and how
    many σ of their difference apart they are when they disagree (None when they agree)."""
    delta = abs(fv - bv)
    # Hausman: var(b − f) = var(b) − var(f) when the filter is the efficient one; else as
    # two independent estimates.
    spread = math.sqrt(bs * bs - fs * fs) if fs < bs else math.hypot(fs, bs)
    disagree = delta > AGREEMENT_SIGMAS * spread and delta > tolerance * abs(bv)
    return (not disagree), (delta / spread if disagree else None)


def _at_bound(b_val: np.ndarray, b_sig: np.ndarray, prior: ParameterEstimate) -> np.ndarray:
    """c_D whose data value (`_balance_data`) lies within `BOUND_SIGMAS` of 0, more tightly
    than the prior."""
    out = np.zeros(len(PARAMETER_NAMES), bool)
    v, s = float(b_val[_C_D]), float(b_sig[_C_D])
    out[_C_D] = math.isfinite(s) and abs(v) <= BOUND_SIGMAS * s and s < float(prior.sigma[_C_D])
    return out


def answer_parameters(
    filter_result: EstimationResult | None, balance: WrenchBalanceResult | None,
    prior: ParameterEstimate,
) -> tuple[ParameterEstimate, tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    """θ per parameter from the filter's result and the balance (module docstring).

    Parameters
    ----------
    filter_result : EstimationResult or None
        The filter and batch estimate (None: it could not follow the flight).
    balance : WrenchBalanceResult or None
        The force and torque balance (None: it determined nothing or could not run).
    prior : ParameterEstimate
        The prior θ and σ (SI).

    Returns
    -------
    estimate : ParameterEstimate
        θ and its covariance, SI.
    status : tuple of 6 str
        `DETERMINED`, `NOT_DETERMINED` or `AT_BOUND` per parameter.
    source : tuple of 6 str
        "filter", "balance" or "prior" per parameter.
    mismatch : tuple of str
        One phrase per parameter where the filter and the balance disagree.

    Raises
    ------
    JobFailedError
        Neither estimate given.
    """
    if filter_result is None and balance is None:
        raise JobFailedError("no estimate to answer from")
    n = len(PARAMETER_NAMES)
    f_est = None if filter_result is None else filter_result.final
    f_det = np.zeros(n, bool) if f_est is None else _filter_determines(f_est)
    b_det = np.zeros(n, bool) if balance is None else np.asarray(balance.determined, bool)
    source = np.full(n, "prior", dtype=object)
    mismatch = []
    b_val, b_sig = _balance_data(balance)
    for j, name in enumerate(PARAMETER_NAMES):
        if f_det[j] and math.isfinite(b_sig[j]):
            assert f_est is not None
            fv, fs = float(f_est.value[j]), float(f_est.sigma[j])
            bv, bs = float(b_val[j]), float(b_sig[j])
            stands, apart = _filter_stands(fv, fs, bv, bs, float(AGREEMENT_TOLERANCE[j]))
            source[j] = "filter" if stands else "balance" if b_det[j] else "prior"
            if apart is not None:
                mismatch.append(
                    f"{name}: filter {fv:.4g} ± {fs:.2g}, balance {bv:.4g} ± {bs:.2g} "
                    f"{PARAMETER_UNITS[name]} ({apart:.1f} σ apart)")
        elif f_det[j]:
            source[j] = "filter"
        elif b_det[j]:
            source[j] = "balance"
    bound = _at_bound(b_val, b_sig, prior) & (source == "prior")
    value = prior.value.astype(float).copy()
    cov = np.diag(prior.sigma**2)
    for name, est in (("filter", f_est), ("balance", None if balance is None
                                          else balance.estimate)):
        idx = np.flatnonzero(source == name)
        if est is None or not idx.size:
            continue
        value[idx] = est.value[idx]
        cov[np.ix_(idx, idx)] = est.covariance[np.ix_(idx, idx)]
    status = [DETERMINED if s != "prior" else NOT_DETERMINED for s in source]
    for j in np.flatnonzero(bound):
        value[j] = max(float(b_val[j]), 0.0)
        cov[j, :] = cov[:, j] = 0.0
        cov[j, j] = float(b_sig[j]) ** 2
        status[j], source[j] = AT_BOUND, "balance"
    return (ParameterEstimate(value, cov), tuple(status), tuple(str(s) for s in source),
            tuple(mismatch))


def _empty_history() -> EstimationHistory:
    return EstimationHistory(
        t=np.zeros(0), theta=np.zeros((0, 6)), theta_sigma=np.zeros((0, 6)),
        position=np.zeros((0, 3)), quaternion=np.zeros((0, 4)),
        innovation=np.zeros((0, MEAS_DIM)), nis=np.zeros(0))


def balance_only_result(balance: WrenchBalanceResult, prior: ParameterEstimate,
                        measurement_sigma: tuple[float, float], pose_source: str,
                        true_theta: np.ndarray | None, notes: tuple[str, ...]
                        ) -> EstimationResult:
    """An `EstimationResult` for a flight the filter could not follow: the balance alone.

    ``filtered`` holds the balance's θ (there is no filter estimate), the history is empty
    and the convergence times NaN.

    Parameters
    ----------
    balance : WrenchBalanceResult
        The force and torque balance's answer.
    prior : ParameterEstimate
        The prior θ and covariance.
    measurement_sigma : tuple of float
        Pose noise: position σ, m, and attitude σ, rad.
    pose_source : str
        Where the pose came from (motion capture, the autopilot's estimate).
    true_theta : ndarray, shape (6,), optional
        The truth of a simulated flight.
    notes : tuple of str
        Notes carried into the result.
    """
    return EstimationResult(
        prior=prior, filtered=balance.estimate, refined=None, history=_empty_history(),
        convergence_time=np.full(len(PARAMETER_NAMES), np.nan), true_theta=true_theta,
        measurement_sigma=measurement_sigma, pose_source=pose_source, notes=notes)


def with_answer(result: EstimationResult, estimate: ParameterEstimate,
                status: tuple[str, ...], source: tuple[str, ...],
                mismatch: tuple[str, ...], balance: WrenchBalanceResult | None,
                filter_refusal: str | None, notes: tuple[str, ...]) -> EstimationResult:
    """``result`` carrying the per-parameter answer (its ``final``) and how it was formed.

    Parameters
    ----------
    result : EstimationResult
        The filter's (or the balance-only) result.
    estimate : ParameterEstimate
        The answer θ and covariance.
    status : tuple of str
        Per parameter: determined, not determined by this flight, at the bound.
    source : tuple of str
        Per parameter: which estimate gave the value (filter, balance, prior).
    mismatch : tuple of str
        Parameters on which filter and balance disagree, in words.
    balance : WrenchBalanceResult or None
        The force and torque balance, if it ran.
    filter_refusal : str or None
        Why the filter's result was not used, if it was not.
    notes : tuple of str
        Notes appended to the result's.
    """
    return replace(result, answer=estimate, status=status, answer_source=source,
                   mismatch=mismatch, balance=balance, filter_refusal=filter_refusal,
                   notes=result.notes + notes)
