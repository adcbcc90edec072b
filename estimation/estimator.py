"""The estimation pipeline behind ``mavsysid estimate``: filter, fit noise, refine, report.

1. The parameter EKF runs over the flight with the vehicle config's noise (the paper's
   estimator): the *filter* estimate and its history over time.
2. Refinement (optional, on by default): the process-noise level is fitted by maximum
   likelihood on the filter's innovations, and a batch MAP estimate of states and θ
   jointly is computed at that level: the *refined* estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation.batch import refine
from estimation.ekf import ParameterEKF
from estimation.flight_data import FlightData
from estimation.noise_fit import fit_noise_scale
from estimation.report import convergence_time
from estimation.results import EstimationResult, ParameterEstimate
from vehicle.config import PARAMETER_NAMES, VehicleConfig
from vehicle.errors import InputError
from vehicle.linearization import initial_state_sigma

__all__ = ["EstimatorSettings", "estimate_parameters", "prior_from_config"]

#: Least flight the estimator accepts, s.
MIN_DURATION = 2.0


@dataclass(frozen=True)
class EstimatorSettings:
    """Choices of the estimation pipeline.

    Attributes
    ----------
    prior_relative_sigma : float
        σ of the prior on each parameter, relative to the config's nominal value.
    refine : bool
        Run the noise fit and the batch MAP refinement after the filter.
    autopilot_position_sigma, autopilot_attitude_sigma : float
        Measurement σ (m, rad) used when the pose comes from the autopilot's own
        estimator (filtered and lagged), instead of the config's motion-capture σ.
    c_D_scale : float
        Prior σ and units of c_D when the config's nominal c_D is 0, s/m.
    """

    prior_relative_sigma: float = 0.5
    refine: bool = True
    autopilot_position_sigma: float = 0.05
    autopilot_attitude_sigma: float = math.radians(1.0)
    c_D_scale: float = 0.01


def prior_from_config(config: VehicleConfig, settings: EstimatorSettings) -> ParameterEstimate:
    """The prior: the config's nominal θ with σ = relative σ × |θ| (c_D: a floor if 0)."""
    if not settings.prior_relative_sigma > 0.0:
        raise InputError(f"prior relative σ {settings.prior_relative_sigma:g}: expected > 0")
    value = config.theta.copy()
    sigma = settings.prior_relative_sigma * np.abs(value)
    if value[1] == 0.0:
        sigma[1] = settings.c_D_scale
    return ParameterEstimate(value, np.diag(sigma**2))


def _measurement_sigma(flight: FlightData, config: VehicleConfig,
                       settings: EstimatorSettings) -> tuple[float, float]:
    if flight.pose_source == "autopilot":
        return settings.autopilot_position_sigma, settings.autopilot_attitude_sigma
    return config.noise.position_sigma, config.noise.attitude_sigma


def _initial_state_sigma(
    flight: FlightData, sigma: tuple[float, float]
) -> tuple[float, float, float, float]:
    """σ of the initial state for this flight (see `initial_state_sigma`)."""
    return initial_state_sigma(sigma[0], sigma[1], float(flight.t[1] - flight.t[0]))


def estimate_parameters(
    flight: FlightData, config: VehicleConfig, settings: EstimatorSettings | None = None
) -> EstimationResult:
    """Estimate θ = [c_T, c_D, c_M, j_x, j_y, j_z] from a flight.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds (from `estimation.readers.load_flight`).
    config : VehicleConfig
        The vehicle: known mass and geometry, nominal θ as the prior, noise.
    settings : EstimatorSettings, optional

    Returns
    -------
    EstimationResult
    """
    settings = settings or EstimatorSettings()
    if flight.duration < MIN_DURATION:
        raise InputError(f"{flight.source}: {flight.duration:.2f} s of data; the estimator "
                         f"needs at least {MIN_DURATION:g} s")
    if flight.rotor_count != config.rotor_count:
        raise InputError(f"{flight.source}: {flight.rotor_count} rotor-speed columns, but "
                         f"vehicle {config.name} has {config.rotor_count} rotors")
    prior = prior_from_config(config, settings)
    sigma = _measurement_sigma(flight, config, settings)
    state_sigma = _initial_state_sigma(flight, sigma)
    ekf = ParameterEKF(config, prior, sigma)
    run = ekf.run(flight, state_sigma)
    notes = list(flight.warnings)

    refined = None
    if settings.refine:
        fit = fit_noise_scale(flight, config, prior, sigma, state_sigma)
        nz = fit.config.noise
        notes.append(
            f"process noise fitted to the flight: {fit.scale:.3g} × the configured densities "
            f"(force {nz.force_density:.3g} N·√s, moment {nz.moment_density:.3g} N·m·√s)"
            + ("; at the edge of the search range" if fit.at_bound else ""))
        batch = refine(flight, fit.run.states, fit.run.estimate,
                       ParameterEKF(fit.config, prior, sigma).model, prior, sigma)
        refined = batch.estimate
        notes.append(f"batch refinement: {batch.iterations} iterations, cost "
                     f"{batch.cost_initial:.4g} → {batch.cost_final:.4g}")

    truth = flight.true_theta
    final = refined if refined is not None else run.estimate
    reference = truth if truth is not None else final.value
    history = run.history
    conv = convergence_time(history.t - history.t[0], history.theta, reference)
    if truth is not None:
        notes.append("true parameters from the simulated flight's meta.json (not used by the "
                     "estimator)")
    if flight.pose_source == "autopilot":
        notes.append("pose from the autopilot's own estimator (filtered and lagged): measurement "
                     f"σ {1000 * sigma[0]:.0f} mm, {math.degrees(sigma[1]):.1f}° assumed")
    weak = [n for n, s in zip(PARAMETER_NAMES, final.relative_sigma, strict=True) if s > 0.2]
    if weak:
        notes.append(f"poorly identified (σ > 20 %): {', '.join(weak)}; the flight did not "
                     "excite them enough")
    return EstimationResult(
        prior=prior, filtered=run.estimate, refined=refined, history=history,
        convergence_time=conv, true_theta=truth, measurement_sigma=sigma,
        pose_source=flight.pose_source, notes=tuple(notes),
    )
