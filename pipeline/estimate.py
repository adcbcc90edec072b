"""One estimation job: read a flight log and estimate θ (the work of ``mavsysid estimate``).

`run_estimate` is what the command line and the tests call; the console layer
(``mavsysid estimate``) only parses its options, calls it and prints. Two estimates come
from the flight: the force and torque balance (`mavsysid.estimation.balance.fit`, with
its held-out check) and the filter with its batch refinement
(`mavsysid.estimation.filter.estimator`). When the balance answers, the filter checks it and θ is
answered per parameter (`mavsysid.estimation.answer`): a filter that cannot
follow the flight, or whose θ is refused (`check_result`: physically impossible, far
outside the prior, contradicting the log's equation-error fit), leaves the balance's
answer, with the reason in the notes. A flight is refused only when neither determines a
parameter. A rotor channel that reads a constant share of its speed is rescaled first
(`mavsysid.estimation.checks.rescale_wrong_rotor`). `estimate_flight` does the same
on a flight already read, and `checked_estimate` gives its answer's θ̂ and Σ (re-planning in
flight, `mavsysid.pipeline.replanned_stream`, and its offline evaluation).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mavsysid.estimation.answer import (
    BOUND_SIGMAS,
    answer_parameters,
    balance_only_result,
    with_answer,
)
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
    prior_from_config,
)
from mavsysid.estimation.filter.guard import check_agreement
from mavsysid.estimation.flight import MIN_DURATION, FlightData
from mavsysid.estimation.progress import report_stage
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import (
    AT_BOUND,
    DETERMINED,
    NOT_DETERMINED,
    EstimationResult,
    ParameterEstimate,
    WrenchBalanceResult,
)
from mavsysid.estimation.robust import widened
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle

from mavsysid.errors import JobFailedError

__all__ = ["EstimateRun", "Estimator", "check_result", "checked_estimate", "estimate_flight",
           "run_estimate"]

#: What estimates θ from a read flight: `estimate_parameters` or a caller's (e.g. with the
#: effects a diagnosis names, `mavsysid.pipeline.auto_effects`).
Estimator = Callable[[FlightData, VehicleConfig, EstimatorSettings | None], EstimationResult]


@dataclass(frozen=True)
class EstimateRun:
    """A finished estimation: the vehicle, the flight as read, and the result."""

    config: VehicleConfig
    flight: FlightData
    result: EstimationResult


def run_estimate(
    log: str | Path, vehicle: str | Path = "firefly", pose: str | Path | None = None,
    time_offset: float | None = None, settings: EstimatorSettings | None = None,
    start: float | None = None, end: float | None = None,
    estimate: Estimator | None = None,
) -> EstimateRun:
    """Read a flight log and estimate θ.

    Parameters
    ----------
    log : str or Path
        ``pose.csv``, ``.tlog``, ``.ulg`` or ``.bin``.
    vehicle : str or Path
        Shipped vehicle name or TOML path: known mass and geometry, and the prior.
    pose : str or Path, optional
        External motion-capture pose CSV to merge with the log's rotor speeds.
    time_offset : float, optional
        Clock offset of ``pose`` relative to the log, s (found by cross-correlation
        when not given).
    settings : EstimatorSettings, optional
    start, end : float, optional
        The window of the log to use, s on its clock (default: `load_flight`'s).
    estimate : Estimator, optional
        Estimates θ from the flight read (default: `estimate_parameters`, the vehicle
        config's model).

    Returns
    -------
    EstimateRun
        With the balance's answer the result carries ``status``, ``answer_source``,
        ``balance`` (and its held-out check), ``mismatch`` and, when the filter could not
        answer, ``filter_refusal``.

    Raises
    ------
    JobFailedError
        The balance determines nothing (or could not run) and the filter's θ is physically
        impossible (c_T, c_D, c_M or J ≤ 0, J breaking the triangle inequality), far
        outside the prior, contradicted by the log's equation-error fit
        (`mavsysid.estimation.filter.guard.check_agreement`), or the filter diverged; one line
        naming the log and both reasons. Also before estimating, when the logged motion
        contradicts the logged tilt: a wrong clock or position unit
        (`mavsysid.estimation.checks.check_kinematics`).
    """
    config = load_vehicle(vehicle)
    flight = load_flight(log, config, pose=pose, time_offset=time_offset, start=start, end=end)
    return estimate_flight(flight, config, settings, estimate)


def estimate_flight(flight: FlightData, config: VehicleConfig,
                    settings: EstimatorSettings | None = None,
                    estimate: Estimator | None = None) -> EstimateRun:
    """θ from a flight already read, as `run_estimate` answers it (its docstring).

    Parameters
    ----------
    flight : FlightData
        The flight as read (`load_flight`).
    config : VehicleConfig
        The vehicle: known mass and geometry, and the prior.
    settings : EstimatorSettings, optional
    estimate : Estimator, optional

    Raises
    ------
    JobFailedError, InputError
        As `run_estimate`.
    """
    check_kinematics(flight)  # a clock or position unit the attitude denies
    settings = settings or EstimatorSettings()
    prior = prior_from_config(config, settings)
    if flight.rotor_count == config.rotor_count:
        flight, _ = rescale_wrong_rotor(flight, config)
    balance, balance_refusal = _balance(flight, config, prior)
    if balance is not None:
        report_stage("the force and torque balance answered; checking it with the filter")
        settings = replace(settings, restart_diverged=False)
    try:
        result = (estimate or estimate_parameters)(flight, config, settings)
        check_result(flight.source, result, config.limits.rotor_speed_max)
    except JobFailedError as error:
        reason = str(error).splitlines()[0].removeprefix(f"{flight.source}: ")
        if balance is None and balance_refusal is None:
            raise
        if balance is None:
            raise JobFailedError(
                f"{flight.source}: this flight determines no parameter: {balance_refusal}; "
                f"and {reason}") from error
        return EstimateRun(config, flight, _answered(None, reason, balance, config, flight,
                                                     prior))
    if balance is None:
        if balance_refusal is not None:
            result = replace(result, notes=result.notes + (
                f"no force and torque balance check: {balance_refusal}",))
        return EstimateRun(config, flight, result)
    return EstimateRun(config, flight, _answered(result, None, balance, config, flight, prior))


def _balance(flight: FlightData, config: VehicleConfig, prior: ParameterEstimate
             ) -> tuple[WrenchBalanceResult | None, str | None]:
    """The force and torque balance, or None and why it gave no answer."""
    if flight.rotor_count != config.rotor_count or flight.duration < MIN_DURATION:
        return None, None  # the estimator says what is wrong with the input
    report_stage("fitting the force and torque balance")
    try:
        return fit_wrench_balance(flight, config, prior), None
    except JobFailedError as error:
        return None, str(error).splitlines()[0].removeprefix(f"{flight.source}: ")
    except np.linalg.LinAlgError:
        return None, "the force and torque balance is numerically singular on this flight"


def _answered(result: EstimationResult | None, filter_refusal: str | None,
              balance: WrenchBalanceResult, config: VehicleConfig, flight: FlightData,
              prior: ParameterEstimate) -> EstimationResult:
    """The per-parameter answer (`mavsysid.estimation.answer`) and its notes."""
    estimate, status, source, mismatch = answer_parameters(result, balance, prior)
    notes = list(balance.notes)
    if result is None:
        notes.append(f"the filter and batch could not follow this flight ({filter_refusal}); "
                     "the answer is the force and torque balance's")
        result = balance_only_result(
            balance, prior, (config.noise.position_sigma, config.noise.attitude_sigma),
            flight.pose_source, flight.true_theta, tuple(flight.warnings))
    if mismatch:
        notes.append("the filter and the force and torque balance disagree on "
                     + "; ".join(mismatch) + ": the balance answers for them (where it "
                     "determines them; not determined where it does not); the model "
                     "misses something (mavsysid diagnose names what)")
    for label, why in ((NOT_DETERMINED, "the prior's value and σ are kept"),
                       (AT_BOUND, f"the data put it within {BOUND_SIGMAS:g} σ of 0")):
        names = [n for n, s in zip(PARAMETER_NAMES, status, strict=True) if s == label]
        if names:
            notes.append(f"{', '.join(names)}: {label}; {why}")
    notes.extend(_triangle_note(estimate, status))
    return with_answer(result, estimate, status, source, mismatch, balance, filter_refusal,
                       tuple(notes))


def _triangle_note(estimate: ParameterEstimate, status: tuple[str, ...]) -> list[str]:
    """A kept prior inertia that breaks the triangle inequality with determined ones."""
    j = estimate.value[3:6]
    known = [s == DETERMINED for s in status[3:6]]
    names = PARAMETER_NAMES[3:6]
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
    """Refuse, in one line naming ``source``, a result `run_estimate` would not print.

    The final θ must be physically possible and near the prior
    (`mavsysid.estimation.checks.check_plausible`), and, for the paper's model, agree
    with the log's own force and torque balance (`mavsysid.estimation.filter.guard.check_agreement`,
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
    final = result.final
    effects = [e.effect for e in result.effects]
    floor = (None if rotor_speed_max is None else
             vanishing_floor(effects, float(final.value[0]), rotor_speed_max))
    check_plausible(source, final.value, final.sigma, result.prior.value, result.prior.sigma,
                    may_vanish=vanishing_parameters(e.name for e in effects), floor=floor)
    if result.equation_error is not None:
        unwidened = final if result.mismatch_widening is None else ParameterEstimate(
            final.value, widened(final.covariance, 1.0 / result.mismatch_widening))
        check_agreement(source, unwidened, result.equation_error)


def checked_estimate(flight: FlightData, config: VehicleConfig,
                     settings: EstimatorSettings | None = None,
                     source: str | None = None) -> ParameterEstimate:
    """θ̂ and Σ (SI) as ``mavsysid estimate`` reports them: the final estimate.

    The per-parameter answer of `estimate_flight`: what the flight does not determine keeps
    the prior's value and σ.

    Parameters
    ----------
    flight : FlightData
        The flight as read (`load_flight`).
    config : VehicleConfig
        The vehicle: known mass and geometry, and the prior.
    settings : EstimatorSettings, optional
        The defaults of ``mavsysid estimate`` when None.
    source : str, optional
        Names the log in a refusal; the flight's source by default.

    Raises
    ------
    JobFailedError
        Refused, as ``estimate`` would refuse it (exit 3).
    InputError
        The log's kinematics are inconsistent (bad input).
    """
    if source is not None:
        flight = replace(flight, source=source)
    return estimate_flight(flight, config, settings).result.final
