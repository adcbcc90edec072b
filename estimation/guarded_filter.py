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
from mavsysid.estimation.ekf import FilterRun
from mavsysid.estimation.equation_error_fit import EquationErrorFit
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.guard import divergence, nis_level
from mavsysid.estimation.plausibility import vanishing_parameters
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.linearization import MEAS_DIM, initial_state_sigma
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import JobFailedError

__all__ = ["MAX_RESTARTS", "filter_attempt", "guarded_filter"]

#: Restarts of a diverged filter from the equation-error θ before the estimate is refused.
MAX_RESTARTS = 2


def filter_attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
) -> tuple[ModelTerms | None, FilterRun | None, str | None]:
    """One filter run: terms, run and why it diverged (None: it did not).

    An entry of θ that ``effects`` let vanish (c_D with ``rotor_drag_linear``) may be ≈ 0.
    """
    state_sigma = initial_state_sigma(sigma[0], sigma[1], float(flight.t[1] - flight.t[0]))
    try:
        terms, run = reference_terms(flight, effects, config, start, sigma, state_sigma)
    except JobFailedError:
        return None, None, "the state overflowed"
    may_vanish = vanishing_parameters(e.name for e in effects)
    return terms, run, divergence(run.history.t, run.history.nis, run.estimate, prior,
                                  may_vanish)


def guarded_filter(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    priors: tuple[ParameterEstimate, ParameterEstimate], sigma: tuple[float, float],
    state_sigma: tuple[float, float, float, float], ee: EquationErrorFit | None,
    notes: list[str],
) -> tuple[ModelTerms, FilterRun, ParameterEstimate, tuple[float, float]]:
    """Step 1 with the divergence guard (`mavsysid.estimation.guard`).

    Filter from ``start``; if it diverged, restart from the equation-error θ with the
    prior's covariance and the measurement σ widened to the innovations' level (at most
    `MAX_RESTARTS` times, while a restart has something new to try); refuse if it still
    diverges. ``priors`` is (the prior, the filter's start). Returns the terms, the run,
    and the start and measurement σ the run used.
    """
    prior, start = priors
    if ee is None:
        terms, run = reference_terms(flight, effects, config, start, sigma, state_sigma)
        return terms, run, start, sigma
    terms, run, reason = filter_attempt(flight, effects, config, start, prior, sigma)
    restart = ParameterEstimate(ee.estimate.value, prior.covariance)
    for _ in range(MAX_RESTARTS):
        if reason is None:
            break
        level = nis_level(run.history.t, run.history.nis)[0] if run is not None else np.nan
        widen = float(np.sqrt(level / MEAS_DIM)) if np.isfinite(level) else 1.0
        widen = max(widen, 1.0)
        if start is restart and widen == 1.0:
            break  # the same run again would diverge again
        start, sigma = restart, (sigma[0] * widen, sigma[1] * widen)
        notes.append(f"the filter diverged ({reason}); restarted from the equation-error θ "
                     f"with the measurement σ × {widen:.3g} (the innovations' level): "
                     f"{1000 * sigma[0]:.2g} mm, {math.degrees(sigma[1]):.2g}°")
        terms, run, reason = filter_attempt(flight, effects, config, start, prior, sigma)
    if reason is not None or terms is None or run is None:
        raise JobFailedError(" ".join(
            f"{flight.source}: the parameter filter diverged, also when restarted from the "
            f"equation-error θ ({reason}); the model cannot follow this log".split()))
    return terms, run, start, sigma
