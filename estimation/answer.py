"""The answer of ``mavsysid estimate``: θ per parameter, the balance checked by the filter.

`estimate` is the one entry point: the force and torque balance
(`mavsysid.estimation.balance.fit`, which follows real data: band, window and
rotor-to-pose offset chosen from the flight, HAC σ widened by the errors in the variables
and by split disagreements) and the filter with its batch refinement
(`mavsysid.estimation.filter.estimator`, the paper's estimator, more precise where its
model and noise assumptions hold) both run; the balance's θ is the filter's
equation-error reference. Per estimated quantity (`answer_parameters`):

* the filter determines it and the balance has a value for it (determined or not): the
  filter's value and σ stand unless a test at the 5 % level (beyond `AGREEMENT_SIGMAS` =
  1.96 σ of their difference, and beyond the quantity's relative tolerance, the accuracy
  asked of the estimator) rejects them. Where the filter is the more precise, the test is
  Hausman's (Hausman 1978): both come from one flight and the filter is the efficient
  estimator when the paper's model holds, so their difference has variance σ_b² − σ_f².
  Where it is not (its σ widened for a mismatch, or a flight it follows poorly), the
  difference is taken as of two independent estimates, σ_b² + σ_f². When the filter is
  rejected the balance answers: its value and σ where it determines the quantity, the
  prior's otherwise; the disagreement is reported as a mismatch (what ``diagnose`` looks
  for), not a refusal;
* one determines it: that one's value and σ (the filter's only when it followed the
  flight);
* neither: c_D whose data value lies within `BOUND_SIGMAS` σ of 0 is "at the bound" (drag
  linear in rotor speed, or none: the value clipped at 0 with the data's σ), unless the
  filter's value contradicts the balance's (then the model misses a law, and a bound with
  the balance's σ would be a confident wrong answer); anything else is "not determined by
  this flight" and keeps the prior's value and σ.

The filter reads the pose, so it estimates θ and the wrench's nuisance quantities; a
sensor's (the IMU's biases and offset, `with_imu_quantities`) are the balance's. With
``EstimatorSettings.filter_imu`` it reads the IMU too
(`mavsysid.estimation.filter.imu_measurement`) and estimates every sensor's quantities.

A filter determines a quantity by the balance's own rule
(`mavsysid.estimation.results.quantity_status`). The covariance keeps the cross terms
within each source and none between sources, but one: where the balance rejects the
filter's value of a quantity, the filter's other quantities are conditioned on that
quantity's answer (`follow_rejected`), and those that leaned on the rejected value (c_M and
j_z on c_D, where the yaw determines only their ratio) follow it, or are no longer
determined. A filter that cannot follow the flight, or
whose θ `check_result` refuses (physically impossible, far outside the prior, contradicted
by the balance), leaves the balance's answer with the reason in the notes; a flight is
refused only when neither determines anything.

Rotor speeds that are motor outputs through the vehicle's motor curve are only as right as
the curve: a common scale s on them (T = c_T n², so c_T and c_M come out as 1/s² of the
truth, c_D and J unchanged) adds its relative σ, twice, to c_T and c_M, fully correlated
(`with_rotor_scale`); a quantity it widens beyond the rule is no longer determined.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from mavsysid.estimation.balance.fit import fit_wrench_balance
from mavsysid.estimation.checks import (
    check_kinematics,
    check_plausible,
    rescale_wrong_rotor,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    estimate_parameters,
)
from mavsysid.estimation.filter.guard import check_agreement
from mavsysid.estimation.flight import MIN_DURATION, FlightData
from mavsysid.estimation.progress import report_stage
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
    prior_from_config,
    quantity_status,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.imu import imu_quantities
from mavsysid.vehicle.linearization import MEAS_DIM
from mavsysid.vehicle.parameters import (
    C_D,
    C_M,
    C_T,
    INERTIA,
    PAPER_THETA,
    PARAMETER_NAMES,
    EstimatedQuantity,
    quantity_names,
)

from mavsysid.errors import JobFailedError

__all__ = ["AGREEMENT_SIGMAS", "BOUND_SIGMAS", "MIN_TORQUE_INPUT_RATE", "FilterEstimator",
           "ParameterAnswer", "answer_parameters", "balance_only_result", "check_result",
           "estimate", "follow_rejected", "with_answer", "with_curve_uncertainty",
           "with_rotor_scale"]

#: What estimates θ with the filter and batch from a read flight, given the balance's θ
#: as the equation-error reference (None: it computes its own): `estimate_parameters`, or
#: a caller's (e.g. with the effects a diagnosis names, `mavsysid.pipeline.auto_effects`).
FilterEstimator = Callable[[FlightData, VehicleConfig, EstimatorSettings | None,
                            ParameterEstimate | None], EstimationResult]


#: Filter and balance disagree beyond this many σ of their difference (and the relative
#: tolerance): the Hausman test at the 5 % level.
AGREEMENT_SIGMAS = Z95
#: A data value within this many σ of 0 puts c_D at its bound.
BOUND_SIGMAS = 2.0
#: Rotor speeds sampled slower than this, Hz, do not resolve the attitude's excitation (a
#: few Hz) for the filter: interpolated between samples, their differences lag and smear
#: the torques, which the filter reads as inertia (ArduCopter SITL's tlog thinned to
#: 10 Hz: j_x +83 % at 5.4 σ, c_T still right). The balance's band stops at 0.15 of the
#: rate; below this rate the torque quantities (c_M, J) are the balance's or none.
MIN_TORQUE_INPUT_RATE = 20.0
_TORQUE = np.array([name == "c_M" or name.startswith("j_") for name in PARAMETER_NAMES])


def _balance_data(balance: WrenchBalanceResult | None, count: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The balance's data value and σ per quantity; σ inf where it has none."""
    if balance is None:
        return np.full(count, np.nan), np.full(count, np.inf)
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
    out = np.zeros(b_val.size, bool)
    v, s = float(b_val[C_D]), float(b_sig[C_D])
    out[C_D] = math.isfinite(s) and abs(v) <= BOUND_SIGMAS * s and s < float(prior.sigma[C_D])
    return out


def _sources(f_est: ParameterEstimate | None, balance: WrenchBalanceResult | None,
             prior: ParameterEstimate, quantities: tuple[EstimatedQuantity, ...],
             excluded: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per quantity, the estimate that answers ("filter", "balance", "prior"), where the
    filter and the balance disagree, and the disagreements in words (module docstring);
    the filter determines none of ``excluded``."""
    n = len(quantities)
    f_det = (np.zeros(n, bool) if f_est is None
             else quantity_status(f_est.value, f_est.sigma, prior.sigma))
    if excluded is not None:
        f_det &= ~excluded
    b_det = np.zeros(n, bool) if balance is None else np.asarray(balance.determined, bool)
    b_val, b_sig = _balance_data(balance, n)
    source = np.full(n, "prior", dtype=object)
    disagree = np.zeros(n, bool)
    mismatch = []
    for j, quantity in enumerate(quantities):
        if f_det[j] and math.isfinite(b_sig[j]):
            assert f_est is not None
            fv, fs = float(f_est.value[j]), float(f_est.sigma[j])
            bv, bs = float(b_val[j]), float(b_sig[j])
            stands, apart = _filter_stands(fv, fs, bv, bs, quantity.tolerance)
            source[j] = "filter" if stands else "balance" if b_det[j] else "prior"
            if apart is not None:
                disagree[j] = True
                mismatch.append(
                    f"{quantity.name}: filter {fv:.4g} ± {fs:.2g}, balance {bv:.4g} ± "
                    f"{bs:.2g} {quantity.unit} ({apart:.1f} σ apart)")
        elif f_det[j]:
            source[j] = "filter"
        elif b_det[j]:
            source[j] = "balance"
    return source, disagree, mismatch


@dataclass(frozen=True)
class ParameterAnswer:
    """The per-quantity answer of `answer_parameters`.

    Attributes
    ----------
    estimate : ParameterEstimate
        The quantities and their covariance, SI.
    status : tuple of str
        `DETERMINED`, `NOT_DETERMINED` or `AT_BOUND` per quantity.
    source : tuple of str
        "filter", "balance" or "prior" per quantity.
    mismatch : tuple of str
        One phrase per quantity where the filter and the balance disagree.
    leaning : tuple of str
        Per quantity whose filter value leans on one the filter was rejected on, and so
        follows that one's answer (`follow_rejected`): its name and the correlation.
    """

    estimate: ParameterEstimate
    status: tuple[str, ...]
    source: tuple[str, ...]
    mismatch: tuple[str, ...]
    leaning: tuple[str, ...] = ()


def answer_parameters(
    filter_result: EstimationResult | None, balance: WrenchBalanceResult | None,
    prior: ParameterEstimate, quantities: tuple[EstimatedQuantity, ...] = PAPER_THETA,
    refused_filter: EstimationResult | None = None, slow_inputs: bool = False,
) -> ParameterAnswer:
    """Each quantity from the filter's result and the balance (module docstring).

    Parameters
    ----------
    filter_result : EstimationResult or None
        The filter and batch estimate (None: it could not follow the flight).
    balance : WrenchBalanceResult or None
        The force and torque balance (None: it determined nothing or could not run).
    prior : ParameterEstimate
        The prior of the quantities (SI).
    quantities : tuple of EstimatedQuantity
        θ and the nuisance quantities (`VehicleConfig.quantities`), in the estimates' order.
    refused_filter : EstimationResult, optional
        A filter result that was refused (`check_result`) and gives no value: where it
        disagrees with the balance, the balance's value is still contradicted, so c_D is
        not put at its bound there.
    slow_inputs : bool
        The rotor speeds were sampled slower than `MIN_TORQUE_INPUT_RATE`: the filter's
        torque quantities (c_M, J) are not taken.

    Returns
    -------
    ParameterAnswer

    Raises
    ------
    JobFailedError
        Neither estimate given.
    """
    if filter_result is None and balance is None:
        raise JobFailedError("no estimate to answer from")
    f_est = None if filter_result is None else filter_result.final.on(prior)
    excluded = np.zeros(len(quantities), bool)
    excluded[:len(PARAMETER_NAMES)] = _TORQUE & slow_inputs
    source, disagree, mismatch = _sources(f_est, balance, prior, quantities, excluded)
    if f_est is None and refused_filter is not None and balance is not None:
        _, disagree, mismatch = _sources(_unwidened(refused_filter).on(prior), balance,
                                         prior, quantities)
    b_val, b_sig = _balance_data(balance, len(quantities))
    # A bound is the answer only where nothing contradicts the balance's value.
    bound = _at_bound(b_val, b_sig, prior) & (source == "prior") & ~disagree
    checker = f_est if f_est is not None or refused_filter is None else _unwidened(
        refused_filter).on(prior)
    if checker is not None and bound[C_D]:  # a filter value that contradicts the bound
        bound[C_D] = _filter_stands(float(checker.value[C_D]), float(checker.sigma[C_D]),
                                    float(b_val[C_D]), float(b_sig[C_D]),
                                    quantities[C_D].tolerance)[0]
    value, cov = _assemble(source, f_est, balance, prior)
    leaning: tuple[str, ...] = ()
    if f_est is not None:
        value, cov, leaning, dropped = follow_rejected(f_est, source, disagree, value, cov,
                                                       prior)
        b_det = np.zeros(len(source), bool) if balance is None else balance.determined
        for k in dropped:
            source[k] = "balance" if b_det[k] else "prior"
            _take_from(k, balance.estimate if source[k] == "balance" else prior, value, cov)
    status = [DETERMINED if s != "prior" else NOT_DETERMINED for s in source]
    for j in np.flatnonzero(bound):
        value[j] = max(float(b_val[j]), 0.0)
        cov[j, :] = cov[:, j] = 0.0
        cov[j, j] = float(b_sig[j]) ** 2
        status[j], source[j] = AT_BOUND, "balance"
    return ParameterAnswer(ParameterEstimate(value, cov, prior.names), tuple(status),
                           tuple(str(s) for s in source), tuple(mismatch), leaning)


def _assemble(source: np.ndarray, f_est: ParameterEstimate | None,
              balance: WrenchBalanceResult | None, prior: ParameterEstimate
              ) -> tuple[np.ndarray, np.ndarray]:
    """Value and covariance per quantity from its source, cross terms within each source."""
    value = prior.value.astype(float).copy()
    cov = np.diag(prior.sigma**2)
    for name, est in (("filter", f_est), ("balance", None if balance is None
                                          else balance.estimate)):
        idx = np.flatnonzero(source == name)
        if est is None or not idx.size:
            continue
        value[idx] = est.value[idx]
        cov[np.ix_(idx, idx)] = est.covariance[np.ix_(idx, idx)]
    return value, cov


def _take_from(j: int, est: ParameterEstimate, value: np.ndarray, cov: np.ndarray) -> None:
    """Quantity j's value and variance from ``est``, without cross terms (in place)."""
    value[j] = est.value[j]
    cov[j, :] = cov[:, j] = 0.0
    cov[j, j] = est.covariance[j, j]


def follow_rejected(f_est: ParameterEstimate, source: np.ndarray, disagree: np.ndarray,
                    value: np.ndarray, cov: np.ndarray, prior: ParameterEstimate
                    ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray]:
    """The filter's answered quantities conditioned on the answer for those it was rejected on.

    Where the balance rejects the filter's value of a quantity (r), the filter's values of
    the others it answers (k) lean on that value through its covariance S: with r's answer
    a ~ N(a, A) in place of the filter's x_r, they become (the Gaussian conditional carried
    over to the new marginal)

        x_k + K (a − x_r),   S_kk − K S_rk + K A Kᵀ,   K = S_kr S_rr⁻¹,

    so a pair the flight determines only as a ratio (c_M and j_z, both scaled by the c_D
    that damps the yaw) does not keep a σ that the rejected c_D's value bought.

    Parameters
    ----------
    f_est : ParameterEstimate
        The filter's estimate on the prior's quantities.
    source : ndarray of str, shape (P,)
        Which estimate answers each quantity ("filter", "balance", "prior").
    disagree : ndarray of bool, shape (P,)
        Where the balance rejected the filter's value.
    value, cov : ndarray, shapes (P,) and (P, P)
        The answer as assembled from the sources, SI.
    prior : ParameterEstimate
        The prior (names, and σ for `quantity_status`).

    Returns
    -------
    value, cov : ndarray
        The answer with the filter's quantities conditioned.
    leaning : tuple of str
        Per filter quantity whose σ at least doubled or whose value moved by more than its
        former σ: its name and its correlation with the rejected quantity it leans on most.
    dropped : ndarray of int
        The filter's quantities no longer determined once conditioned (`quantity_status`).
    """
    rejected = np.flatnonzero(disagree & (source != "filter"))
    kept = np.flatnonzero(source == "filter")
    if not rejected.size or not kept.size:
        return value, cov, (), np.zeros(0, int)
    s = f_est.covariance
    gain = np.linalg.solve(s[np.ix_(rejected, rejected)], s[np.ix_(rejected, kept)]).T
    answered = cov[np.ix_(rejected, rejected)]
    value, cov = value.copy(), cov.copy()
    value[kept] = f_est.value[kept] + gain @ (value[rejected] - f_est.value[rejected])
    cov[np.ix_(kept, kept)] = (s[np.ix_(kept, kept)] - gain @ s[np.ix_(rejected, kept)]
                               + gain @ answered @ gain.T)
    cov[np.ix_(kept, rejected)] = gain @ answered
    cov[np.ix_(rejected, kept)] = cov[np.ix_(kept, rejected)].T
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    old_sigma = f_est.sigma
    moved = (sigma[kept] >= 2.0 * old_sigma[kept]) | (
        np.abs(value[kept] - f_est.value[kept]) > old_sigma[kept])
    leaning = []
    corr = s / np.sqrt(np.outer(np.diag(s), np.diag(s)))
    for j, k in enumerate(kept):
        if moved[j]:
            r = rejected[int(np.argmax(np.abs(corr[k, rejected])))]
            leaning.append(f"{prior.names[k]} (correlation {corr[k, r]:+.2f} with "
                           f"{prior.names[r]})")
    still = quantity_status(value, sigma, prior.sigma)
    return value, cov, tuple(leaning), kept[~still[kept]]


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


def estimate(flight: FlightData, config: VehicleConfig,
             settings: EstimatorSettings | None = None,
             filter_estimate: FilterEstimator | None = None) -> EstimationResult:
    """θ of a flight, answered per parameter (module docstring): what ``estimate`` prints.

    The force and torque balance (`mavsysid.estimation.balance.fit.fit_wrench_balance`)
    and the filter with its batch refinement (`estimate_parameters`) both run; the
    balance's θ is the filter's equation-error reference (restart point, agreement check).
    Where the balance determines something, the answer is formed per parameter
    (`answer_parameters`): a filter that cannot follow the flight, or whose θ `check_result`
    refuses, leaves the balance's answer, with the reason in the notes. A flight is refused
    only when neither determines a parameter. A rotor channel that reads a constant share
    of its speed is rescaled first (`mavsysid.estimation.checks.rescale_wrong_rotor`).

    Parameters
    ----------
    flight : FlightData
        The flight as read (`mavsysid.estimation.readers.load_flight`).
    config : VehicleConfig
        The vehicle: known mass and geometry, and the prior.
    settings : EstimatorSettings, optional
    filter_estimate : FilterEstimator, optional
        Estimates θ with the filter (default `estimate_parameters`, the vehicle config's
        model).

    Returns
    -------
    EstimationResult
        With the balance's answer it carries ``status``, ``answer_source``, ``balance``
        (and its held-out check), ``mismatch`` and, when the filter could not answer,
        ``filter_refusal``; ``final`` is the answer.

    Raises
    ------
    JobFailedError
        Neither the balance nor the filter determines a parameter: the balance determines
        nothing (or could not run) and the filter's θ is physically impossible, far
        outside the prior, contradicted by the balance, or the filter diverged; one line
        naming the log and both reasons.
    InputError
        The logged motion contradicts the logged tilt: a wrong clock or position unit
        (`mavsysid.estimation.checks.check_kinematics`).
    """
    wind = check_kinematics(flight)
    if wind is not None:
        flight = replace(flight, warnings=(*flight.warnings, wind))
    settings = settings or EstimatorSettings()
    config = with_imu_quantities(config, flight, every_sensor=settings.filter_imu)
    prior = prior_from_config(config, settings)
    if flight.rotor_count == config.rotor_count:
        flight, _ = rescale_wrong_rotor(flight, config)
    balance, balance_refusal = _balance(flight, config, prior)
    filter_config, settings, reference = _filter_inputs(config, settings, balance,
                                                        balance_refusal is None, prior)
    result: EstimationResult | None = None
    try:
        result = (filter_estimate or estimate_parameters)(flight, filter_config, settings,
                                                          reference)
        check_result(flight.source, result, config.limits.rotor_speed_max)
    except JobFailedError as error:
        reason = str(error).splitlines()[0].removeprefix(f"{flight.source}: ")
        if balance_refusal is None and balance is None:
            raise
        if balance_refusal is not None:
            force = "" if wind is None else "; " + wind.removeprefix(f"{flight.source}: ")
            raise JobFailedError(
                f"{flight.source}: this flight determines no parameter: {balance_refusal}; "
                f"and {reason}{force}") from error
        assert balance is not None
        return _answered(None, reason, balance, config, flight, prior, refused=result)
    assert result is not None
    if balance_refusal is not None:
        result = replace(result, notes=result.notes + (
            f"no force and torque balance check: {balance_refusal}",))
    if balance_refusal is not None or balance is None:
        return _filter_with_curve_uncertainty(result, flight.rotor_scale_sigma)
    return _answered(result, None, balance, config, flight, prior)


def _filter_with_curve_uncertainty(result: EstimationResult, scale_sigma: float
                                   ) -> EstimationResult:
    """A filter's answer alone with the motor curve's uncertainty (`with_rotor_scale`)."""
    if scale_sigma <= 0.0:
        return result
    everything = np.ones(result.final.value.size, bool)
    return replace(result, answer=with_rotor_scale(result.final, scale_sigma, everything),
                   notes=result.notes + (_curve_note(scale_sigma, ["c_T", "c_M"]),))


def _curve_note(scale_sigma: float, names: list[str]) -> str:
    """What the motor curve's uncertainty added, in words."""
    return (f"rotor speeds are motor outputs through the motor curve, known to "
            f"{100 * scale_sigma:.2g} %: the σ of {' and '.join(names)} holds twice that")


def _filter_inputs(config: VehicleConfig, settings: EstimatorSettings,
                   balance: WrenchBalanceResult | None, answered: bool,
                   prior: ParameterEstimate
                   ) -> tuple[VehicleConfig, EstimatorSettings, ParameterEstimate | None]:
    """The filter's vehicle, settings and equation-error reference (the balance's θ on the
    filter's quantities); a balance that answered keeps the filter from restarting."""
    reference = None if balance is None else balance.with_prior(prior)
    if balance is not None and answered:
        report_stage("the force and torque balance answered; checking it with the filter")
        settings = replace(settings, restart_diverged=False)
    filter_config = config if settings.filter_imu else _pose_filter_config(config)
    if reference is not None:
        reference = reference.subset(quantity_names(filter_config.extra_quantities))
    return filter_config, settings, reference


def _pose_filter_config(config: VehicleConfig) -> VehicleConfig:
    """The vehicle as a filter reading the pose alone models it: the nuisance quantities of
    the wrench only (a sensor's terms are the balance's)."""
    return replace(config, extra_quantities=tuple(
        q for q in config.extra_quantities if q.term is None or q.term.channel == "wrench"))


def with_imu_quantities(config: VehicleConfig, flight: FlightData, every_sensor: bool = False
                        ) -> VehicleConfig:
    """The vehicle with the nuisance quantities the flight's IMU brings.

    For the balance: where it takes the specific force from the accelerometer (a flight
    without a motion-capture pose, `mavsysid.estimation.signals.balance_segments`), its
    biases and, where neither the vehicle file nor the log states it, the IMU's offset from
    the centre of gravity (`mavsysid.vehicle.imu.imu_quantities`); the gyro's bias is
    measured against the pose's rates and taken off before (`mavsysid.estimation.signals`).
    For a filter that reads the IMU (``every_sensor``): every sensor's.

    Parameters
    ----------
    config : VehicleConfig
    flight : FlightData
    every_sensor : bool
        Both sensors' biases and the offset, whatever the pose.
    """
    imu = flight.imu
    if imu is None or imu.gyro is None or imu.accel is None:
        return config
    if not every_sensor and flight.pose_source == "motion_capture":
        return config
    named = {q.name for q in config.extra_quantities}
    extras = tuple(q for q in imu_quantities(
        every_sensor, True, imu.position is not None, config.noise.gyro_bias_sigma,
        config.noise.accel_bias_sigma) if q.name not in named)
    return replace(config, extra_quantities=config.extra_quantities + extras)


def _balance(flight: FlightData, config: VehicleConfig, prior: ParameterEstimate
             ) -> tuple[WrenchBalanceResult | None, str | None]:
    """The force and torque balance, and why it gives no answer (None: it answers).

    A balance that runs but determines nothing is returned with its reason: its θ is still
    the filter's equation-error reference.
    """
    if flight.rotor_count != config.rotor_count or flight.duration < MIN_DURATION:
        return None, None  # the filter says what is wrong with the input
    report_stage("fitting the force and torque balance")
    try:
        balance = fit_wrench_balance(flight, config, prior)
    except JobFailedError as error:
        return None, str(error).splitlines()[0].removeprefix(f"{flight.source}: ")
    except np.linalg.LinAlgError:
        return None, "the force and torque balance is numerically singular on this flight"
    if not balance.determined[:len(PAPER_THETA)].any():  # a sensor's bias alone is no answer
        return balance, ("the force and torque balance determines no parameter of θ (every "
                         f"σ above {100 * MAX_RELATIVE_SIGMA:g} % of its value)")
    return balance, None


def _answered(result: EstimationResult | None, filter_refusal: str | None,
              balance: WrenchBalanceResult, config: VehicleConfig, flight: FlightData,
              prior: ParameterEstimate, refused: EstimationResult | None = None
              ) -> EstimationResult:
    """The per-parameter answer (`answer_parameters`) and its notes; ``refused``, a filter
    result `check_result` refused, still says where the balance is contradicted."""
    rate = None if flight.inputs is None else flight.inputs.slowest_rate
    slow = rate is not None and rate < MIN_TORQUE_INPUT_RATE
    answer = answer_parameters(result, balance, prior, config.quantities, refused, slow)
    answer, curve = with_curve_uncertainty(answer, flight.rotor_scale_sigma, prior)
    estimate, status, source, mismatch = (answer.estimate, answer.status, answer.source,
                                          answer.mismatch)
    notes = [*balance.notes, *curve]
    if result is None:
        notes.append(f"the filter and batch could not follow this flight ({filter_refusal}); "
                     "the answer is the force and torque balance's")
        # The σ the refused filter used (an autopilot's pose: the larger assumed one).
        sigma = (refused.measurement_sigma if refused is not None
                 else (config.noise.position_sigma, config.noise.attitude_sigma))
        result = balance_only_result(balance, prior, sigma, flight.pose_source,
                                     flight.true_theta, tuple(flight.warnings))
    result = replace(result, prior=prior)
    if mismatch:
        notes.append("the filter and the force and torque balance disagree on "
                     + "; ".join(mismatch) + ": the balance answers for them (where it "
                     "determines them; not determined where it does not); the model "
                     "misses something (mavsysid diagnose names what)")
    if slow and result is not None:
        notes.append(f"rotor speeds sampled at {rate:.3g} Hz (below "
                     f"{MIN_TORQUE_INPUT_RATE:g} Hz) do not resolve the attitude's torques "
                     "for the filter: c_M and J are the balance's, where it determines them")
    if answer.leaning:
        notes.append("the filter's " + ", ".join(answer.leaning) + " lean on a value the "
                     "balance rejected: value and σ follow that quantity's answer")
    for label, why in ((NOT_DETERMINED, "the prior's value and σ are kept"),
                       (AT_BOUND, f"the data put it within {BOUND_SIGMAS:g} σ of 0")):
        names = [n for n, s in zip(estimate.names, status, strict=True) if s == label]
        if names:
            notes.append(f"{', '.join(names)}: {label}; {why}")
    notes.extend(_triangle_note(estimate, status))
    return with_answer(result, estimate, status, source, mismatch, balance, filter_refusal,
                       tuple(notes))


def with_rotor_scale(estimate: ParameterEstimate, scale_sigma: float,
                     determined: np.ndarray) -> ParameterEstimate:
    """``estimate`` with the rotor speeds' scale uncertainty on c_T and c_M (module docstring).

    Parameters
    ----------
    estimate : ParameterEstimate
        SI; θ first.
    scale_sigma : float
        Relative 1σ of the rotor speeds' common scale.
    determined : ndarray of bool, shape (P,)
        The quantities the data gave (a prior's σ already holds the scale).

    Returns
    -------
    ParameterEstimate
        Σ + σ² g gᵀ, g = −2 (c_T, 0, c_M, 0, …) on the determined c_T and c_M.
    """
    g = np.zeros(estimate.value.size)
    for j in (C_T, C_M):
        if determined[j]:
            g[j] = -2.0 * float(estimate.value[j])
    widened = estimate.covariance + scale_sigma**2 * np.outer(g, g)
    return ParameterEstimate(estimate.value, widened, estimate.names)


def with_curve_uncertainty(answer: ParameterAnswer, scale_sigma: float,
                           prior: ParameterEstimate) -> tuple[ParameterAnswer, list[str]]:
    """The answer with the motor curve's uncertainty (`with_rotor_scale`), and its note.

    Parameters
    ----------
    answer : ParameterAnswer
    scale_sigma : float
        Relative 1σ of the rotor speeds' scale (0: measured; the answer is returned as is).
    prior : ParameterEstimate
        What a quantity widened beyond `MAX_RELATIVE_SIGMA` falls back to.

    Returns
    -------
    ParameterAnswer, list of str
        The widened answer (c_T, c_M no longer determined where too wide) and its note.
    """
    if scale_sigma <= 0.0:
        return answer, []
    status, source = list(answer.status), list(answer.source)
    determined = np.array([s == DETERMINED for s in status])
    widened = with_rotor_scale(answer.estimate, scale_sigma, determined)
    value, cov = widened.value.copy(), widened.covariance.copy()
    names = [PARAMETER_NAMES[j] for j in (C_T, C_M) if determined[j]]
    lost = []
    for j in (C_T, C_M):
        relative = math.sqrt(cov[j, j]) / abs(value[j]) if value[j] else math.inf
        if determined[j] and relative > MAX_RELATIVE_SIGMA:
            _take_from(j, prior, value, cov)
            status[j], source[j] = NOT_DETERMINED, "prior"
            lost.append(PARAMETER_NAMES[j])
    if not names:
        return answer, []
    note = _curve_note(scale_sigma, names)
    if lost:
        note += f" ({', '.join(lost)} then not determined)"
    return replace(answer, estimate=ParameterEstimate(value, cov, widened.names),
                   status=tuple(status), source=tuple(source)), [note]


def _triangle_note(estimate: ParameterEstimate, status: tuple[str, ...]) -> list[str]:
    """A kept prior inertia that breaks the triangle inequality with determined ones."""
    j = estimate.value[INERTIA]
    known = [s == DETERMINED for s in status[INERTIA]]
    names = PARAMETER_NAMES[INERTIA]
    out = []
    for k in range(3):
        others = [i for i in range(3) if i != k]
        if not known[k] and all(known[i] for i in others) and j[k] > j[others[0]] + j[others[1]]:
            out.append(f"the prior {names[k]} = {j[k]:.3g} kg·m² exceeds "
                       f"{names[others[0]]} + {names[others[1]]} = "
                       f"{j[others[0]] + j[others[1]]:.3g} kg·m² (determined): the rigid-body "
                       f"bound a vehicle file should respect")
    return out


def check_result(source: str, result: EstimationResult,
                 rotor_speed_max: float | None = None) -> None:
    """Refuse, in one line naming ``source``, a filter result `estimate` would not print.

    The final θ must be physically possible and near the prior
    (`mavsysid.estimation.checks.check_plausible`), and, for the paper's model, agree with
    the flight's force and torque balance (`mavsysid.estimation.filter.guard.check_agreement`,
    judged on the σ before the disagreement widened it).

    Parameters
    ----------
    source : str
        The log, as named in the message.
    result : EstimationResult
        The estimate to check.
    rotor_speed_max : float, optional
        Top rotor speed, rad/s: with a linear rotor drag in the model, c_D may go as low as
        keeps the rotor drag a drag up to it (`mavsysid.estimation.checks.vanishing_floor`).

    Raises
    ------
    JobFailedError
    """
    final, prior = result.final.theta, result.prior.theta
    effects = [e.effect for e in result.effects]
    floor = (None if rotor_speed_max is None else
             vanishing_floor(effects, float(final.value[C_T]), rotor_speed_max))
    check_plausible(source, final.value, final.sigma, prior.value, prior.sigma,
                    may_vanish=vanishing_parameters(e.name for e in effects), floor=floor)
    if result.equation_error is not None:
        check_agreement(source, _unwidened(result), result.equation_error)


def _unwidened(result: EstimationResult) -> ParameterEstimate:
    """The filter's final estimate with its σ as before a disagreement widened it."""
    final, factor = result.final, result.mismatch_widening
    return final if factor is None else ParameterEstimate(
        final.value, final.covariance / np.outer(factor, factor), final.names)
