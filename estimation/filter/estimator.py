"""The filter side of ``mavsysid estimate``: filter, fit noise, refine.

0. Known model effects (the config's ``[effects.NAME]`` tables, or effects a caller such
   as the discrepancy workflow passes) put the flight in the model's terms; by default
   their parameters are fitted jointly with θ and the noise level first
   (`mavsysid.estimation.filter.likelihood`). Without effects this step is absent and the
   results are exactly the paper's model's.
1. The parameter EKF runs over the flight with the vehicle config's noise (the paper's
   estimator), guarded against divergence (`mavsysid.estimation.filter.guard`): the
   *filter* estimate and its history over time.
2. Refinement (optional, on by default): the process-noise level is fitted by maximum
   likelihood on the filter's innovations, and a batch MAP estimate of states and θ
   jointly is computed at that level (`mavsysid.estimation.batch.refine`): the *refined*
   estimate. The batch reads the pose alone: where the filter reads the IMU
   (`mavsysid.estimation.filter.imu_measurement`), the refined estimate is the filter's
   at the fitted noise level instead, so less data never replaces more.

The equation-error θ of the force and torque balance is the guard's reference: the
restart point, the agreement check, and the widening of σ where the two disagree. The
estimated quantities are θ and the config's nuisance quantities
(`mavsysid.vehicle.parameters`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.balance.fit import WrenchBalanceSettings, fit_wrench_balance
from mavsysid.estimation.batch.refine import refine
from mavsysid.estimation.filter.ekf import FilterRun, ParameterEKF
from mavsysid.estimation.filter.guard import guarded_filter, pose_sigma
from mavsysid.estimation.filter.likelihood import (
    NOISE_SCALE_LIMITS,
    EffectFit,
    ModelTerms,
    fit_effect_parameters,
    fit_noise_scale,
)
from mavsysid.estimation.flight import MIN_DURATION, FlightData
from mavsysid.estimation.progress import report_stage
from mavsysid.estimation.results import (
    C_D_PRIOR_SIGMA,
    PRIOR_RELATIVE_SIGMA,
    EstimationResult,
    FittedEffect,
    ParameterEstimate,
    convergence_time,
    prior_from_config,
)
from mavsysid.estimation.robust import disagreement_widening, widened
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig
from mavsysid.vehicle.linearization import initial_state_sigma
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import InputError, JobFailedError

__all__ = ["EstimatorSettings", "estimate_parameters", "estimate_with_effects",
           "flight_initial_state_sigma"]


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
    fit_effects : bool
        Fit the parameters of the config's model effects jointly with θ (else hold them
        at the config's values); used by `estimate_parameters`.
    guard : bool
        Check the filter against the equation-error θ, the force and torque balance's
        (`mavsysid.estimation.balance.fit`): restart a diverged filter from it, widen σ
        where it disagrees and refuse a final θ it contradicts
        (`mavsysid.estimation.filter.guard`).
    start_from_equation_error : bool
        Start the filter at the equation-error θ (with the prior's covariance) rather than
        at the prior; the MAP prior stays the vehicle file's either way.
    restart_diverged : bool
        Restart a diverged filter from the equation-error θ (else refuse at once: used when
        the force and torque balance answers and the filter only checks it).
    filter_imu : bool
        The filter reads the flight's IMU too, its biases and offset as filter states
        (`mavsysid.estimation.filter.imu_measurement`); the batch refinement, which reads
        the pose alone, is then left out. Off by default: measured in docs/benchmarks.md
        ("What the IMU adds"), it tightens θ on simulated flights but costs 2–3× the time,
        and the force and torque balance reads the IMU either way.
    """

    prior_relative_sigma: float = PRIOR_RELATIVE_SIGMA
    refine: bool = True
    autopilot_position_sigma: float = 0.05
    autopilot_attitude_sigma: float = math.radians(1.0)
    c_D_scale: float = C_D_PRIOR_SIGMA
    fit_effects: bool = True
    guard: bool = True
    start_from_equation_error: bool = False
    restart_diverged: bool = True
    filter_imu: bool = False


def _measurement_sigma(flight: FlightData, config: VehicleConfig,
                       settings: EstimatorSettings) -> tuple[tuple[float, float], str | None]:
    """The σ assumed for the pose source, raised to the log's measured noise if larger."""
    if flight.pose_source == "autopilot":
        assumed = settings.autopilot_position_sigma, settings.autopilot_attitude_sigma
    else:
        assumed = config.noise.position_sigma, config.noise.attitude_sigma
    return pose_sigma(flight, assumed)


def flight_initial_state_sigma(
    flight: FlightData, sigma: tuple[float, float]
) -> tuple[float, float, float, float]:
    """σ of the filter's initial state for this flight, at its first sample interval.

    Parameters
    ----------
    flight : FlightData
        The flight; its first two sample times set the interval, s.
    sigma : tuple of 2 float
        Measurement σ of position (m) and attitude (rad).

    Returns
    -------
    tuple of 4 float
        σ of position (m), velocity (m/s), attitude (rad) and body rates (rad/s);
        see `mavsysid.vehicle.linearization.initial_state_sigma`.
    """
    return initial_state_sigma(sigma[0], sigma[1], float(flight.t[1] - flight.t[0]))


def _check_inputs(flight: FlightData, config: VehicleConfig,
                  effects: Sequence[ModelEffect]) -> tuple[ModelEffect, ...]:
    if flight.duration < MIN_DURATION:
        raise InputError(f"{flight.source}: {flight.duration:.2f} s of data; the estimator "
                         f"needs at least {MIN_DURATION:g} s")
    if flight.rotor_count != config.rotor_count:
        raise InputError(f"{flight.source}: {flight.rotor_count} rotor-speed columns, but "
                         f"vehicle {config.name} has {config.rotor_count} rotors")
    effects = tuple(effects)
    for effect in effects:
        if not isinstance(effect, ModelEffect):
            raise InputError(f"model effect {effect!r}: expected a mavsysid.vehicle.model_effects "
                             "ModelEffect")
    names = [e.name for e in effects]
    if len(set(names)) < len(names):
        raise InputError(f"model effects {', '.join(names)}: each effect at most once")
    return effects


def _effect_note(fit: EffectFit) -> str:
    parts = []
    for fe in fit.effects:
        values = ", ".join(f"{p.name} = {v:.4g} ± {s:.2g} {p.unit}" for p, v, s in
                           zip(fe.effect.parameters, fe.value, fe.sigma, strict=True))
        parts.append(f"{fe.name} ({values})")
    return (f"model effects fitted jointly with θ by maximum likelihood: {'; '.join(parts)} "
            f"[{fit.evaluations} filter passes]; θ's σ includes their uncertainty")


def _with_increment(estimate: ParameterEstimate | None, increment: np.ndarray | None
                    ) -> ParameterEstimate | None:
    if estimate is None or increment is None:
        return estimate
    return ParameterEstimate(estimate.value, estimate.covariance + increment, estimate.names)


def estimate_parameters(
    flight: FlightData, config: VehicleConfig, settings: EstimatorSettings | None = None,
    reference: ParameterEstimate | None = None,
) -> EstimationResult:
    """Estimate θ = [c_T, c_D, c_M, j_x, j_y, j_z] from a flight, with the config's effects.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds (from `mavsysid.estimation.readers.load_flight`).
    config : VehicleConfig
        The vehicle: known mass and geometry, nominal θ as the prior, noise, and its model
        effects (``config.effects``; fitted unless ``settings.fit_effects`` is off).
    settings : EstimatorSettings, optional
    reference : ParameterEstimate, optional
        The equation-error θ (the balance's with the prior,
        `mavsysid.estimation.results.WrenchBalanceResult.with_prior`); fitted here when
        ``settings.guard`` asks for it and none is given.

    Returns
    -------
    EstimationResult
    """
    settings = settings or EstimatorSettings()
    return estimate_with_effects(flight, config, config.effects,
                                 settings, fit_effects=settings.fit_effects,
                                 reference=reference)


def estimate_with_effects(
    flight: FlightData, config: VehicleConfig, effects: Sequence[ModelEffect],
    settings: EstimatorSettings | None = None, fit_effects: bool = True,
    reference: ParameterEstimate | None = None,
) -> EstimationResult:
    """Estimate θ under the given model effects, fitting their parameters jointly.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds as logged.
    config : VehicleConfig
        Known mass and geometry, nominal θ as the prior, noise. Its own ``effects`` are
        *not* added: ``effects`` is the complete list.
    effects : sequence of ModelEffect
        The effects the model includes, each at most once; their values are the start of
        the fit (or the values used when ``fit_effects`` is False). Empty: the paper's
        model, identical to the estimator without effects.
    settings : EstimatorSettings, optional
        ``settings.fit_effects`` is ignored here in favour of ``fit_effects``.
    fit_effects : bool
        Estimate the effects' parameters (maximum likelihood,
        `mavsysid.estimation.filter.likelihood`); False holds them at the given values.
    reference : ParameterEstimate, optional
        The equation-error θ, as for `estimate_parameters`.

    Returns
    -------
    EstimationResult
        ``effects`` holds each effect with its (fitted) values and σ; θ's covariances
        include the effects' uncertainty when fitted.
    """
    settings = settings or EstimatorSettings()
    effects = _check_inputs(flight, config, effects)
    prior = prior_from_config(config, settings)
    sigma, sigma_note = _measurement_sigma(flight, config, settings)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    notes = list(flight.warnings) + ([sigma_note] if sigma_note else [])
    ee = None
    if settings.guard:
        ee = reference if reference is not None else _reference(flight, config, prior, notes)
    start = prior
    if ee is not None and settings.start_from_equation_error:
        start = ParameterEstimate(ee.value, prior.covariance, prior.names)
        notes.append("filter started at the equation-error θ")

    fit, used = _effects(flight, config, effects, fit_effects, start, sigma, state_sigma,
                         notes)
    effects = tuple(fe.effect for fe in used)
    report_stage(f"filtering {len(flight)} samples")
    terms, run, start, sigma = guarded_filter(flight, effects, config, (prior, start), sigma,
                                              state_sigma, ee, notes, settings.restart_diverged)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    log_likelihood, refined = run.log_likelihood, None
    densities = (config.noise.force_density, config.noise.moment_density)
    if settings.refine:
        refined, log_likelihood, densities = _refine(terms, run, fit, config, (prior, start),
                                                     sigma, state_sigma, notes)
    increment = None if fit is None else fit.theta_covariance_increment()
    filtered, refined = (_with_increment(e, increment) for e in (run.estimate, refined))
    widening = None
    if ee is not None and not effects:
        filtered, refined, widening = _widen_by_disagreement(filtered, refined, ee, notes)
    truth = flight.true_theta
    final = refined if refined is not None else filtered
    history = run.history
    six = len(PARAMETER_NAMES)
    conv = convergence_time(history.t - history.t[0], history.theta[:, :six],
                            truth if truth is not None else final.value[:six])
    notes.extend(_closing_notes(flight, sigma, final))
    return EstimationResult(
        prior=prior, filtered=filtered, refined=refined, history=history,
        convergence_time=conv, true_theta=truth, measurement_sigma=sigma,
        pose_source=flight.pose_source, notes=tuple(notes), effects=used,
        log_likelihood=log_likelihood,
        equation_error=None if ee is None or effects else ee,
        mismatch_widening=widening,
        process_noise=densities, pose_rate=flight.pose_rate,
    )


def _effects(
    flight: FlightData, config: VehicleConfig, effects: tuple[ModelEffect, ...], fit: bool,
    start: ParameterEstimate, sigma: tuple[float, float],
    state_sigma: tuple[float, float, float, float], notes: list[str],
) -> tuple[EffectFit | None, tuple[FittedEffect, ...]]:
    """Step 0: the effects' parameters fitted jointly with θ, or held (with a note)."""
    if fit and any(e.parameters for e in effects):
        report_stage("fitting the model effects' parameters")
        result = fit_effect_parameters(flight, config, effects, start, sigma, state_sigma)
        notes.append(_effect_note(result))
        return result, result.effects
    if effects:
        notes.append("model effects held at the given values: "
                     + "; ".join(repr(e) for e in effects))
    return None, tuple(FittedEffect(e, np.full(len(e.parameters), np.nan), False)
                       for e in effects)


def _widen_by_disagreement(
    filtered: ParameterEstimate, refined: ParameterEstimate | None, ee: ParameterEstimate,
    notes: list[str],
) -> tuple[ParameterEstimate, ParameterEstimate | None, np.ndarray]:
    """The final θ's σ widened where the equation-error θ disagrees (model mismatch)."""
    final = refined if refined is not None else filtered
    factor = disagreement_widening(final.value, final.sigma, ee.value, ee.sigma)
    if np.all(factor == 1.0):
        return filtered, refined, factor
    wide = ", ".join(f"{n} ×{f:.3g}" for n, f in zip(final.names, factor, strict=True)
                     if f > 1.0)
    notes.append(f"σ widened where the equation-error θ disagrees beyond both σ ({wide}): the "
                 "physics differ from the model; --auto-effects or mavsysid diagnose names "
                 "what it misses")
    final = ParameterEstimate(final.value, widened(final.covariance, factor), final.names)
    return (filtered, final, factor) if refined is not None else (final, None, factor)


def _reference(flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
               notes: list[str]) -> ParameterEstimate | None:
    """The equation-error θ (the balance's with the prior), or None with a note."""
    try:
        balance = fit_wrench_balance(flight, config, prior,
                                     WrenchBalanceSettings(holdout_fraction=0.0))
    except (JobFailedError, np.linalg.LinAlgError) as error:
        notes.append(f"no equation-error check: {str(error).splitlines()[0]}")
        return None
    return balance.with_prior(prior)


def _refine(
    terms: ModelTerms, unit_run: FilterRun, fit: EffectFit | None, config: VehicleConfig,
    priors: tuple[ParameterEstimate, ParameterEstimate], sigma: tuple[float, float],
    state_sigma: tuple[float, float, float, float], notes: list[str],
) -> tuple[ParameterEstimate, float, tuple[float, float]]:
    """Step 2: the process-noise level (the effect fit's, or fitted now) and the batch MAP.

    ``priors`` is (the MAP prior, the filter's start); ``unit_run`` the filter run on
    ``terms`` from that start at the configured noise (the noise fit's first point).
    Appends its notes to ``notes``;
    returns the refined θ, the log-likelihood of the filter run at the fitted noise
    level and that level's force and moment densities (N·√s, N·m·√s). A noise level at
    the upper edge of its search range is refused (`JobFailedError`).
    """
    prior, start_prior = priors
    if fit is not None:
        noise_cfg, scale, at_bound = fit.config, fit.noise_scale, fit.noise_at_bound
        # The effect fit searches `NOISE_SCALE_BOUNDS`, which straddle 1.
        at_upper = at_bound and scale > 1.0
        start, terms_r = fit.run, fit.terms
    else:
        report_stage("fitting the process noise")
        nf = fit_noise_scale(terms.flight, config, start_prior, sigma, state_sigma,
                             wrench=terms.wrench, unit_run=unit_run)
        noise_cfg, scale, at_bound, start, terms_r = nf.config, nf.scale, nf.at_bound, \
            nf.run, terms
        at_upper = nf.at_upper_bound
    nz = noise_cfg.noise
    if at_upper:
        # At the upper edge the filter needs more unmodelled force than any range allows:
        # the model does not fit. (At the lower edge it fits better than configured.)
        raise JobFailedError(
            f"{terms.flight.source}: the process-noise fit ended at the edge of its range "
            f"({scale:.3g} × the configured densities, at most {NOISE_SCALE_LIMITS[1]:g}); "
            "the model does not describe this log's forces")
    notes.append(
        f"process noise fitted to the flight: {scale:.3g} × the configured densities "
        f"(force {nz.force_density:.3g} N·√s, moment {nz.moment_density:.3g} N·m·√s)"
        + ("; at the edge of the search range" if at_bound else ""))
    if ParameterEKF(noise_cfg, prior, sigma).reads(terms_r.flight.imu) is not None:
        # The shooting cost has no IMU residuals: its θ would stand on less data than the
        # filter's and replace it.
        notes.append("no batch refinement: it reads the pose alone, the filter read the IMU "
                     "too; the estimate is the filter's at the fitted process noise")
        return start.estimate, start.log_likelihood, (nz.force_density, nz.moment_density)
    report_stage("batch refinement")
    flight, states, wrench = terms_r.flight, start.states, terms_r.wrench
    if len(flight.segment_starts) > 1:
        # The batch's states form one chain of shooting nodes: it must not bridge a gap.
        i = flight.longest_segment()
        a, b = flight.segment_bounds[i]
        flight, states = flight.segment(i), states[a:b]
        wrench = None if wrench is None else wrench[a:b]
        notes.append(f"batch refinement on the longest segment only (t = {flight.t[0]:.3f} "
                     f"to {flight.t[-1]:.3f} s, {i + 1} of "
                     f"{len(terms_r.flight.segment_starts)}); the filter used all segments")
    batch = refine(flight, states, start.estimate,
                   ParameterEKF(noise_cfg, prior, sigma).model, prior, sigma, wrench=wrench)
    notes.append(f"batch refinement: {batch.iterations} iterations, cost "
                 f"{batch.cost_initial:.4g} → {batch.cost_final:.4g}")
    return batch.estimate, start.log_likelihood, (nz.force_density, nz.moment_density)


def _closing_notes(flight: FlightData, sigma: tuple[float, float],
                   final: ParameterEstimate) -> list[str]:
    """Notes on the truth's source, an autopilot pose and weakly identified parameters."""
    notes = []
    if flight.true_theta is not None:
        notes.append("true parameters from the simulated flight's meta.json (not used by the "
                     "estimator)")
    if flight.pose_source == "autopilot":
        notes.append("pose from the autopilot's own estimator (filtered and lagged): measurement "
                     f"σ {1000 * sigma[0]:.0f} mm, {math.degrees(sigma[1]):.1f}° assumed")
    weak = [n for n, s in zip(PARAMETER_NAMES, final.theta.relative_sigma, strict=True)
            if s > 0.2]
    if weak:
        notes.append(f"poorly identified (σ > 20 %): {', '.join(weak)}; the flight did not "
                     "excite them enough")
    return notes
