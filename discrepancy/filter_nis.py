"""The parameter EKF's normalised innovation squared (NIS) for the diagnosis' gap.

`mavsysid.discrepancy.diagnosis` reports the NIS of the filter run with the model's known
effects and with the named ones added (held at the regression's values), on the held-out
samples: a consistent filter's NIS averages the measurement dimension.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from mavsysid.estimation import (
    NIS_FACTOR,
    FlightData,
    nis_level,
    report_stage,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import JobFailedError

__all__ = ["filter_nis", "nis_pair"]


def filter_nis(flight: FlightData, config: VehicleConfig, effects: Sequence[ModelEffect],
               grid: np.ndarray) -> np.ndarray:
    """The parameter EKF's NIS with ``effects`` in the model at their values, on ``grid``.

    The estimator's effect channels (`mavsysid.estimation.estimate_with_effects`, held
    values, filter only) carry every catalogue effect, wrenches included. The filter runs
    on the logged samples (it needs no uniform rate); each grid sample of a resampled
    flight takes the NIS of the logged sample nearest to it. The estimator's guard (its
    equation-error fit, restarts and θ checks) is left out: this run measures how well the
    model follows the log, and θ is not reported. A run whose NIS level is beyond the
    guard's divergence bound (`mavsysid.estimation.filter.guard.NIS_FACTOR`) raises
    `JobFailedError`, as an overflowed one does.

    Parameters
    ----------
    flight : FlightData
        The logged flight.
    config : VehicleConfig
        The vehicle, its θ the identified one.
    effects : sequence of ModelEffect
        Effects in the model, held at their values.
    grid : ndarray, shape (M,)
        Times at which the NIS is wanted, s (``flight.t`` itself: every sample).
    """
    from mavsysid.estimation import (
        EstimatorSettings,
        estimate_with_effects,
    )

    result = estimate_with_effects(flight, config, tuple(effects),
                                   EstimatorSettings(refine=False, guard=False),
                                   fit_effects=False)
    nis = np.asarray(result.history.nis, float)
    level, bound = nis_level(result.history.t, nis)
    if level > NIS_FACTOR * bound:
        raise JobFailedError(f"{flight.source}: the parameter filter diverged (mean NIS "
                             f"{level:.3g}, {level / bound:.3g}× its χ² bound)")
    if grid is flight.t:
        return nis
    t = flight.t
    i = np.clip(np.searchsorted(t, grid), 1, len(t) - 1)
    nearest = np.where(grid - t[i - 1] <= t[i] - grid, i - 1, i)
    return nis[nearest]


def nis_pair(flight: FlightData, config: VehicleConfig, known: tuple[ModelEffect, ...],
              fitted: tuple[ModelEffect, ...], grid: np.ndarray
              ) -> tuple[np.ndarray | None, np.ndarray | None, list[str]]:
    """NIS without and with the named effects on ``grid`` (`filter_nis`), and notes.

    An EKF that cannot follow the log (`JobFailedError`, a diverged filter) under the
    model without the named effects is what a mismatch looks like: its NIS is then
    missing, with a note. Only when nothing was named is it a refusal (exit 3, the
    filter's reason): the log then contradicts the model so grossly (a wrong vehicle,
    rotor order, or time on the ground) that "no significant discrepancy" from the
    residual regression would be a confident wrong answer. A filter that cannot follow
    the augmented model (its effects held at the regression's values) costs only its NIS.

    Parameters
    ----------
    flight : FlightData
        The logged flight.
    config : VehicleConfig
        The vehicle, its θ the identified one.
    known : tuple of ModelEffect
        Effects the model already had.
    fitted : tuple of ModelEffect
        The named effects, at their fitted values.
    grid : ndarray, shape (M,)
        Times at which the NIS is wanted, s.
    """
    notes: list[str] = []
    report_stage("parameter filter without the named effects (NIS)")
    try:
        before = filter_nis(flight, config, known, grid)
    except JobFailedError as error:
        if not fitted:
            raise
        before = None
        notes.append(f"no NIS without the named effects: {error}")
    if not fitted:
        return before, before, notes
    report_stage("parameter filter with the named effects (NIS)")
    try:
        after = filter_nis(flight, config, (*known, *fitted), grid)
    except JobFailedError as error:
        after = None
        notes.append(f"no NIS with the named effects: {error}")
    return before, after, notes
