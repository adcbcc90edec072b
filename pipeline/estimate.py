"""One estimation job: read a flight log and estimate θ (the work of ``mavsysid estimate``).

`run_estimate` is what the command line and the tests call; the console layer
(``mavsysid estimate``) only parses its options, calls it and prints. An estimate that is
physically impossible or far outside the prior is refused here
(`mavsysid.estimation.plausibility`), before anything is written. `checked_estimate` takes
the same steps on a flight already read and gives θ̂ and Σ as ``estimate`` reports them
(re-planning in flight, `mavsysid.pipeline.replanned_stream`, and its offline evaluation).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mavsysid.estimation.estimator import EstimatorSettings, estimate_parameters
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.guard import check_agreement
from mavsysid.estimation.plausibility import (
    check_plausible,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import EstimationResult, ParameterEstimate
from mavsysid.estimation.robust_covariance import widened
from mavsysid.estimation.tilt_consistency import check_kinematics
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

__all__ = ["EstimateRun", "Estimator", "check_result", "checked_estimate", "run_estimate"]

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

    Raises
    ------
    JobFailedError
        The final θ is physically impossible (c_T, c_D, c_M or J ≤ 0, J breaking the
        triangle inequality) or far outside the prior, or the log's equation-error fit
        contradicts it (`mavsysid.estimation.guard.check_agreement`); one line naming the
        log, the parameter and the numbers. Also before estimating, when the logged motion
        contradicts the logged tilt: a wrong clock or position unit
        (`mavsysid.estimation.tilt_consistency.check_kinematics`).
    """
    config = load_vehicle(vehicle)
    flight = load_flight(log, config, pose=pose, time_offset=time_offset, start=start, end=end)
    check_kinematics(flight)  # a clock or position unit the attitude denies
    result = (estimate or estimate_parameters)(flight, config, settings)
    check_result(flight.source, result, config.limits.rotor_speed_max)
    return EstimateRun(config, flight, result)


def check_result(source: str, result: EstimationResult,
                 rotor_speed_max: float | None = None) -> None:
    """Refuse, in one line naming ``source``, a result `run_estimate` would not print.

    The final θ must be physically possible and near the prior
    (`mavsysid.estimation.plausibility.check_plausible`), and, for the paper's model, agree
    with the log's own force and torque balance (`mavsysid.estimation.guard.check_agreement`,
    judged on the σ before the disagreement widened it).

    Parameters
    ----------
    source : str
        The log, as named in the message.
    result : EstimationResult
        The estimate to check.

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

    The kinematics check, `estimate_parameters` and `check_result`.

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
    check_kinematics(flight)
    result = estimate_parameters(flight, config, settings)
    check_result(flight.source if source is None else source, result)
    return result.final
