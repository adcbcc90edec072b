"""Step 1 of the estimator with its divergence guard: filter, restart, or refuse.

A filter run counts as diverged when its NIS level or its θ says so
(`mavsysid.estimation.guard.divergence`), or when its state overflowed. It is restarted
from the equation-error θ (`mavsysid.estimation.equation_error_fit`) with the prior's
covariance, its measurement σ widened by √(NIS level / m) (the innovations measure the
noise the filter met). The batch refinement never starts from a diverged filter: after
`MAX_RESTARTS` the estimate is refused (`JobFailedError`, one line).
"""

from __future__ import annotations

import math

import numpy as np
from mavsysid.estimation.effect_channels import ModelTerms
from mavsysid.estimation.effect_fit import reference_terms
from mavsysid.estimation.ekf import FilterOverflow, FilterRun
from mavsysid.estimation.equation_error_fit import EquationErrorFit
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.guard import (
    DIVERGED_NIS,
    correlated_noise_sigma,
    divergence,
    nis_level,
)
from mavsysid.estimation.plausibility import vanishing_floor, vanishing_parameters
from mavsysid.estimation.pose_noise import NOISE_TOLERANCE
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.linearization import MEAS_DIM, initial_state_sigma
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import JobFailedError

__all__ = ["DECORRELATION_PASSES", "MAX_RESTARTS", "OVERFLOW_SHARE", "decorrelated_attempt",
           "failure_phrase", "filter_attempt", "guarded_filter"]

#: Filter passes that may raise the measurement σ for correlated pose noise.
DECORRELATION_PASSES = 3

#: Share of an overflowed run's innovations (the first ones) that measure the pose noise.
OVERFLOW_SHARE = 0.75

#: Restarts of a diverged filter from the equation-error θ before the estimate is refused.
MAX_RESTARTS = 2


def failure_phrase(reason: str | None) -> str:
    """What a failed run did: diverged (innovations, overflow) or ended at an impossible θ.

    Parameters
    ----------
    reason : str or None
        `mavsysid.estimation.guard.divergence`'s phrase, or "the state overflowed".
    """
    if reason is None or reason.startswith((DIVERGED_NIS, "the state overflowed")):
        return f"diverged ({reason})"
    return f"ended at a θ that is not physical ({reason})"


def filter_attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
) -> tuple[ModelTerms | None, FilterRun | None, str | None]:
    """One filter run: terms, run and why it diverged (None: it did not).

    An entry of θ that ``effects`` let vanish (c_D with ``rotor_drag_linear``) may be ≈ 0,
    or as low as physics allows beside them (`mavsysid.estimation.plausibility`).
    """
    terms, run, reason, _ = _attempt(flight, effects, config, start, prior, sigma)
    return terms, run, reason


def _attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
) -> tuple[ModelTerms | None, FilterRun | None, str | None, np.ndarray]:
    """`filter_attempt` and the run's innovations (N, 6); of an overflowed run, those
    of its first `OVERFLOW_SHARE` of samples (its last ones are the blow-up)."""
    state_sigma = initial_state_sigma(sigma[0], sigma[1], float(flight.t[1] - flight.t[0]))
    try:
        terms, run = reference_terms(flight, effects, config, start, sigma, state_sigma)
    except FilterOverflow as error:
        innovation = error.innovation[:int(OVERFLOW_SHARE * error.innovation.shape[0])]
        return None, None, "the state overflowed", innovation
    except JobFailedError:
        return None, None, "the state overflowed", np.empty((0, MEAS_DIM))
    may_vanish = vanishing_parameters(e.name for e in effects)
    floor = vanishing_floor(effects, float(run.estimate.value[0]),
                            config.limits.rotor_speed_max)
    return terms, run, divergence(run.history.t, run.history.nis, run.estimate, prior,
                                  may_vanish, floor), run.history.innovation


def decorrelated_attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
    notes: list[str],
) -> tuple[ModelTerms | None, FilterRun | None, str | None, tuple[float, float]]:
    """`filter_attempt`, rerun with σ widened while its innovations are correlated.

    A pose whose noise drifts (an on-board estimator's) makes the innovations correlated;
    the filter at white-noise σ is overconfident and fits θ to the drift. Each pass
    raises σ to `mavsysid.estimation.guard.correlated_noise_sigma` of the last run's
    innovations (an overflowed run's too) when that is clearly larger (a filter at too
    small a σ follows the drift and sees only part of it, hence up to
    `DECORRELATION_PASSES` passes). Returns also the σ of the returned run.
    """
    terms, run, reason, innovation = _attempt(flight, effects, config, start, prior, sigma)
    for _ in range(DECORRELATION_PASSES):
        target = correlated_noise_sigma(innovation)
        wider = tuple(t if t > NOISE_TOLERANCE * s else s
                      for t, s in zip(target, sigma, strict=True))
        if wider == sigma:
            break
        sigma = wider  # type: ignore[assignment]
        notes.append(f"the filter's innovations are correlated in time (pose noise that "
                     f"drifts): measurement σ raised to {1000 * sigma[0]:.2g} mm, "
                     f"{math.degrees(sigma[1]):.2g}°, the white σ of equal information")
        terms, run, reason, innovation = _attempt(flight, effects, config, start, prior,
                                                  sigma)
    return terms, run, reason, sigma


def guarded_filter(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    priors: tuple[ParameterEstimate, ParameterEstimate], sigma: tuple[float, float],
    state_sigma: tuple[float, float, float, float], ee: EquationErrorFit | None,
    notes: list[str], restart: bool = True,
) -> tuple[ModelTerms, FilterRun, ParameterEstimate, tuple[float, float]]:
    """Step 1 with the divergence guard (`mavsysid.estimation.guard`).

    Filter from ``start``; if it diverged, restart from the equation-error θ with the
    prior's covariance and the measurement σ widened to the innovations' level (at most
    `MAX_RESTARTS` times, while a restart has something new to try); refuse if it still
    diverges, unless widening σ for correlated pose noise (`decorrelated_attempt`, from
    the equation-error θ) ends the divergence. ``priors`` is (the prior, the filter's
    start). Returns the terms, the run, and the start and measurement σ the run used.
    ``restart`` False refuses at the first failure (another estimate answers instead).
    """
    prior, start = priors
    if ee is None:
        terms, run = reference_terms(flight, effects, config, start, sigma, state_sigma)
        return terms, run, start, sigma
    terms, run, reason = filter_attempt(flight, effects, config, start, prior, sigma)
    if reason is not None and not restart:
        raise JobFailedError(f"{flight.source}: the parameter filter {failure_phrase(reason)}")
    from_ee = ParameterEstimate(ee.estimate.value, prior.covariance)
    for _ in range(MAX_RESTARTS):
        if reason is None:
            break
        level = nis_level(run.history.t, run.history.nis)[0] if run is not None else np.nan
        widen = float(np.sqrt(level / MEAS_DIM)) if np.isfinite(level) else 1.0
        widen = max(widen, 1.0)
        if start is from_ee and widen == 1.0:
            break  # the same run again would diverge again
        start, sigma = from_ee, (sigma[0] * widen, sigma[1] * widen)
        notes.append(f"the filter {failure_phrase(reason)}; restarted from the equation-error θ "
                     f"with the measurement σ × {widen:.3g} (the innovations' level): "
                     f"{1000 * sigma[0]:.2g} mm, {math.degrees(sigma[1]):.2g}°")
        terms, run, reason = filter_attempt(flight, effects, config, start, prior, sigma)
    if reason is not None:  # last resort: pose noise that drifts (an on-board estimator's)
        start = from_ee
        terms, run, reason, sigma = decorrelated_attempt(flight, effects, config, start,
                                                         prior, sigma, notes)
    if reason is not None or terms is None or run is None:
        raise JobFailedError(" ".join(
            f"{flight.source}: the parameter filter {failure_phrase(reason)}, also when restarted "
            "from the equation-error θ; the model cannot follow this log".split()))
    return terms, run, start, sigma
