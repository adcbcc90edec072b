"""θ re-estimated with the effects the diagnosis names (``mavsysid estimate --auto-effects``).

Under a model mismatch (wind, a pose delay, a motor lag, rotor drag linear in rotor speed
…) the estimator's θ is biased, and no widening of its σ makes the 95 % interval cover
the truth (``bench/mismatch_coverage.py``): the bias must be removed. The diagnosis
(`mavsysid.discrepancy.diagnosis.diagnose_flight`) names the effects the log shows; with
them in the model (`mavsysid.estimation.filter.estimator.estimate_with_effects`, their parameters
fitted jointly with θ) the bias goes and the σ include the effects' uncertainty.

`estimate_with_named_effects`:

1. estimate θ under the vehicle config's model (`estimate_parameters`);
2. diagnose the same flight from that θ (the residual regression and forward selection,
   without the filter's NIS), the config's effects as known;
3. if it names effects, estimate θ again with the config's and the named effects, all
   fitted; otherwise keep step 1's result. Notes say what was named and why.

A first estimate that is refused (`JobFailedError`: a diverged filter, a process-noise fit
at its edge) is diagnosed from the config's θ instead; if the diagnosis names nothing the
refusal stands. `run_estimate_with_named_effects` is `run_estimate` (read the log, the
plausibility checks) with this estimator.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from mavsysid.discrepancy.diagnosis import Diagnosis, DiagnosisSettings, diagnose_flight
from mavsysid.discrepancy.selection import FittedEffect
from mavsysid.estimation import (
    EstimationResult,
    EstimatorSettings,
    FlightData,
    ParameterEstimate,
    estimate_parameters,
    estimate_with_effects,
)
from mavsysid.pipeline.estimate import EstimateRun, run_estimate
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import InputError, JobFailedError

__all__ = ["estimate_with_named_effects", "named_effect_note", "run_estimate_with_named_effects"]


def named_effect_note(effect: FittedEffect) -> str:
    """One effect the diagnosis named, its fitted values and why (BIC gain, p-value).

    Parameters
    ----------
    effect : FittedEffect
        From `Diagnosis.effects`.

    Returns
    -------
    str
        E.g. ``"wind (x = 1.6 ± 0.02 m/s, y = 1.2 ± 0.02 m/s; BIC −812, p = 1e-40)"``.
    """
    values = ", ".join(f"{p.name} = {v:.3g} ± {s:.2g} {p.unit}" for p, v, s in
                       zip(effect.effect.parameters, effect.effect.values, effect.sigma,
                           strict=True))
    return f"{effect.effect.name} ({values}; BIC {effect.delta_bic:.4g}, p = {effect.p_value:.2g})"


def _diagnose(flight: FlightData, config: VehicleConfig, theta: np.ndarray,
              known: tuple[ModelEffect, ...], settings: DiagnosisSettings | None
              ) -> tuple[Diagnosis | None, str | None]:
    """The diagnosis from ``theta``, or None and why (a flight too short to diagnose)."""
    try:
        return diagnose_flight(flight, config, theta, settings, known_effects=known,
                               with_nis=False), None
    except InputError as error:
        return None, f"no diagnosis of the model's effects: {error}"


def estimate_with_named_effects(
    flight: FlightData, config: VehicleConfig, settings: EstimatorSettings | None = None,
    diagnosis_settings: DiagnosisSettings | None = None,
    reference: ParameterEstimate | None = None,
) -> tuple[EstimationResult, tuple[ModelEffect, ...]]:
    """Estimate θ, name the effects the flight shows, and estimate θ again with them.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds as logged.
    config : VehicleConfig
        Known mass and geometry, the prior, noise and the known model effects
        (``config.effects``).
    settings : EstimatorSettings, optional
        Of both estimates; the re-estimate fits the parameters of the known and the named
        effects whatever ``settings.fit_effects`` says (the named ones' values are only the
        regression's start).
    diagnosis_settings : DiagnosisSettings, optional
        Of the diagnosis (candidates, held-out fraction …).
    reference : ParameterEstimate, optional
        The equation-error θ of both estimates (`mavsysid.estimation.estimate_parameters`).

    Returns
    -------
    result : EstimationResult
        The re-estimate with the named effects, or the first estimate when none was
        named; its notes end with what was named and why.
    named : tuple of ModelEffect
        The named effects at their diagnosis values (empty when none).

    Raises
    ------
    JobFailedError
        The first estimate was refused and the diagnosis names nothing that would change
        the model, or the re-estimate is refused.
    """
    settings = settings or EstimatorSettings()
    known = tuple(config.effects)
    try:
        first: EstimationResult | None = estimate_parameters(flight, config, settings,
                                                            reference)
        refusal = None
    except JobFailedError as error:
        first, refusal = None, error
    if first is not None:
        theta = first.final.theta.value
        known = tuple(fe.effect for fe in first.effects)
    else:
        theta = config.theta
    diagnosis, why_not = _diagnose(flight, config, theta, known, diagnosis_settings)
    if diagnosis is None or not diagnosis.effects:
        if refusal is not None:
            raise refusal
        assert first is not None  # one of the two is set
        note = why_not or ("the diagnosis named no effect the model lacks: θ under the "
                           "vehicle config's model")
        return replace(first, notes=(*first.notes, note)), ()
    named = tuple(f.effect for f in diagnosis.effects)
    result = estimate_with_effects(flight, config, diagnosis.augmented_effects, settings,
                                   fit_effects=True, reference=reference)
    start = ("the first estimate" if first is not None else
             f"the vehicle config's θ (the first estimate was refused: {refusal})")
    note = (f"the diagnosis (from {start}) named "
            + "; ".join(named_effect_note(f) for f in diagnosis.effects)
            + ": θ estimated again with them in the model, their parameters fitted jointly")
    return replace(result, notes=(*result.notes, note)), named


def _estimate(flight: FlightData, config: VehicleConfig, settings: EstimatorSettings | None,
              reference: ParameterEstimate | None) -> EstimationResult:
    """`estimate_with_named_effects`' result alone (a `FilterEstimator` of `run_estimate`)."""
    return estimate_with_named_effects(flight, config, settings, reference=reference)[0]


def run_estimate_with_named_effects(
    log: str | Path, vehicle: str | Path = "firefly", pose: str | Path | None = None,
    time_offset: float | None = None, settings: EstimatorSettings | None = None,
    start: float | None = None, end: float | None = None,
) -> EstimateRun:
    """`mavsysid.pipeline.estimate.run_estimate` with `estimate_with_named_effects`.

    Parameters and result as for `run_estimate` (the log, the vehicle, the window; the
    same plausibility checks, which let c_D be ≈ 0 when ``rotor_drag_linear`` was named).

    Parameters
    ----------
    log : str or Path
        ``pose.csv``, ``.tlog``, ``.ulg`` or ``.bin``.
    vehicle : str or Path
        Shipped vehicle name or TOML path.
    pose : str or Path, optional
        External motion-capture pose CSV to merge.
    time_offset : float, optional
        Clock offset of ``pose`` relative to the log, s.
    settings : EstimatorSettings, optional
        Estimator settings (default: the defaults).
    start, end : float, optional
        The window of the log to use, s on its clock.
    """
    return run_estimate(log, vehicle, pose, time_offset, settings, start=start, end=end,
                        filter_estimate=_estimate)
