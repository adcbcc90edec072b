"""How much the evaluation's headline figures move with the draw of experiments.

The paper's Table compares medians over experiments; with twenty experiments a median
moves by several per cent from one set of prior draws to another, and the two headline
figures (the ratio of median reached D-opt and the reduction of the summed convergence
time) move with it. A paired bootstrap over experiments (an experiment's planned and
random flights stay together, since they share the prior draw) gives a percentile
interval for both, so a reader can tell a real difference from the luck of the draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsysid.experiments.evaluation import (
    last_flights,
    median_convergence_time,
    paired_flight_arrays,
)
from scipy.stats import bootstrap

__all__ = ["OFF_PATH_RMS", "SATURATED_SHARE", "HeadlineFigures", "flights_beyond",
           "headline_figures", "headline_intervals", "off_path_flights", "saturating_flights"]

#: A flight whose tracking RMS exceeds this (m) left its plan: the true vehicle could not
#: fly it (a real one would likely have crashed).
OFF_PATH_RMS = 0.5
#: A flight saturated when a rotor sat at a limit on more than this share of the ticks.
SATURATED_SHARE = 0.05

#: Planner kinds compared by the headline figures: planned, baseline.
_PLANNED, _BASELINE = "dopt", "random"


@dataclass(frozen=True)
class HeadlineFigures:
    """The two headline figures with their bootstrap percentile intervals.

    Attributes
    ----------
    dopt_ratio : float
        Median reached D-opt of the random flights over that of the planned flights.
    convergence_reduction : float
        1 − (summed convergence time planned) / (summed convergence time random); a
        parameter whose median never settles counts as the whole flight.
    dopt_ratio_interval, convergence_reduction_interval : tuple of float
        (low, high) percentile interval at ``confidence``.
    confidence : float
    resamples : int
    experiments : int
    """

    dopt_ratio: float
    convergence_reduction: float
    dopt_ratio_interval: tuple[float, float]
    convergence_reduction_interval: tuple[float, float]
    confidence: float
    resamples: int
    experiments: int


def _summed_convergence(t: np.ndarray, ratios: np.ndarray) -> float:
    conv = median_convergence_time(t, ratios)
    return float(np.sum(np.where(np.isnan(conv), t[-1], conv)))


def headline_figures(t: np.ndarray, dopt: dict[str, np.ndarray],
                     ratios: dict[str, np.ndarray]) -> np.ndarray:
    """D-opt ratio and convergence reduction of one set of experiments.

    Parameters
    ----------
    t : ndarray, shape (T,)
        Flight-time grid of the histories, s.
    dopt : dict of str to ndarray, shape (E,)
        Reached D-opt per experiment, for ``"dopt"`` and ``"random"``.
    ratios : dict of str to ndarray, shape (E, T, 6)
        Estimate over truth per experiment.

    Returns
    -------
    ndarray, shape (2,)
        [random / planned median D-opt, 1 − planned / random summed convergence time]
        (NaN when the random flights' sum is 0).
    """
    ratio = np.median(dopt[_BASELINE]) / np.median(dopt[_PLANNED])
    planned = _summed_convergence(t, ratios[_PLANNED])
    baseline = _summed_convergence(t, ratios[_BASELINE])
    reduction = 1.0 - planned / baseline if baseline > 0.0 else np.nan
    return np.array([ratio, reduction])


def headline_intervals(records: list[dict[str, Any]], confidence: float = 0.95,
                       resamples: int = 2000, seed: int = 0) -> HeadlineFigures | None:
    """Headline figures with paired-bootstrap percentile intervals over experiments.

    Returns None when the records lack either planner kind or hold fewer than two
    experiments with both. The same records and ``seed`` give the same intervals.
    """
    arrays = paired_flight_arrays(records, (_PLANNED, _BASELINE))
    if arrays is None:
        return None
    t, dopt, ratios = arrays
    count = len(dopt[_PLANNED])
    if count < 2:
        return None

    def statistic(index: np.ndarray) -> np.ndarray:
        i = np.asarray(index, dtype=int)
        return headline_figures(t, {k: v[i] for k, v in dopt.items()},
                                {k: v[i] for k, v in ratios.items()})

    point = statistic(np.arange(count))
    result = bootstrap((np.arange(count),), statistic, vectorized=False,
                       n_resamples=resamples, confidence_level=confidence,
                       method="percentile", rng=np.random.default_rng(seed))
    low, high = result.confidence_interval
    return HeadlineFigures(float(point[0]), float(point[1]),
                           (float(low[0]), float(high[0])), (float(low[1]), float(high[1])),
                           confidence, resamples, count)


def flights_beyond(records: list[dict[str, Any]], field: str, threshold: float
                   ) -> dict[str, tuple[int, int]]:
    """Per planner kind, (flights whose ``field`` exceeds ``threshold``, flights with the
    field recorded), last iteration of each experiment. Records made before the field was
    recorded are left out."""
    counts = {}
    for kind in dict.fromkeys(f["kind"] for r in records for f in r["flights"]):
        values = [f[field] for f in last_flights(records, kind) if f.get(field) is not None]
        if values:
            counts[kind] = (sum(x > threshold for x in values), len(values))
    return counts


def saturating_flights(records: list[dict[str, Any]], threshold: float = SATURATED_SHARE
                       ) -> dict[str, tuple[int, int]]:
    """`flights_beyond` for a rotor saturated on more than ``threshold`` of the ticks."""
    return flights_beyond(records, "saturated_fraction", threshold)


def off_path_flights(records: list[dict[str, Any]], threshold: float = OFF_PATH_RMS
                     ) -> dict[str, tuple[int, int]]:
    """`flights_beyond` for a tracking RMS over ``threshold``, m."""
    return flights_beyond(records, "tracking_rms", threshold)
