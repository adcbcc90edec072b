"""Tests of the evaluation's headline figures and their bootstrap intervals."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from mavsysid.experiments.evaluation_intervals import (
    headline_figures,
    headline_intervals,
    off_path_flights,
    saturating_flights,
)

TRUTH = [8.5e-6, 0.0176, 1.37e-7, 0.0348, 0.0459, 0.0977]
T = np.arange(0.0, 10.0 + 1e-9, 0.1)


def _history(settle: float, start: float = 1.3) -> dict[str, list]:
    """Estimates that start at ``start`` × truth and sit on the truth from ``settle`` s."""
    factor = np.where(settle > T, start, 1.0)
    theta = factor[:, None] * np.array(TRUTH)[None, :]
    return {"t": T.tolist(), "theta": theta.tolist()}


def _flight(kind: str, dopt: float, settle: float, iteration: int = 0,
            saturated: float | None = None, tracking: float | None = None) -> dict[str, Any]:
    f = {"kind": kind, "iteration": iteration, "reached_dopt": dopt,
         "history": _history(settle)}
    if saturated is not None:
        f["saturated_fraction"] = saturated
    if tracking is not None:
        f["tracking_rms"] = tracking
    return f


def _records(planned: np.ndarray, random: np.ndarray, settle=(1.0, 4.0)) -> list[dict]:
    return [{"truth": TRUTH, "flights": [_flight("dopt", p, settle[0]),
                                         _flight("random", r, settle[1])]}
            for p, r in zip(planned, random, strict=True)]


def test_identical_experiments_give_a_zero_width_interval_at_the_exact_figures():
    """Every experiment 5× better and converging at 1 s vs 4 s: ratio 5, reduction 75 %."""
    planned = np.full(12, 2e-12)
    h = headline_intervals(_records(planned, 5.0 * planned))
    assert h is not None
    assert h.dopt_ratio == pytest.approx(5.0)
    assert h.convergence_reduction == pytest.approx(0.75)
    assert h.dopt_ratio_interval == pytest.approx((5.0, 5.0))
    assert h.convergence_reduction_interval == pytest.approx((0.75, 0.75))
    assert h.experiments == 12


@pytest.mark.parametrize("count", [10, 80])
def test_interval_holds_the_point_and_is_seeded(count):
    """The interval holds the point figure, and the same seed gives the same interval."""
    rng = np.random.default_rng(count)
    planned = 1e-12 * rng.lognormal(0.0, 0.8, count)
    records = _records(planned, 4.0e-12 * rng.lognormal(0.0, 0.8, count))
    a, b = headline_intervals(records, seed=3), headline_intervals(records, seed=3)
    assert a == b
    assert a.dopt_ratio_interval[0] <= a.dopt_ratio <= a.dopt_ratio_interval[1]
    assert a.dopt_ratio_interval[0] < a.dopt_ratio_interval[1]


def test_interval_narrows_with_more_experiments():
    """Eight times the experiments from one distribution give a narrower D-opt interval."""
    rng = np.random.default_rng(7)
    planned = 1e-12 * rng.lognormal(0.0, 0.8, 160)
    random = 4.0e-12 * rng.lognormal(0.0, 0.8, 160)
    few = headline_intervals(_records(planned[:20], random[:20]))
    many = headline_intervals(_records(planned, random))
    assert np.ptp(many.dopt_ratio_interval) < 0.6 * np.ptp(few.dopt_ratio_interval)


def test_experiments_are_resampled_in_pairs():
    """Planned and random flights of one experiment stay together: correlated D-opt across
    experiments (a hard prior draw hurts both) cancels in the ratio."""
    spread = np.geomspace(1e-13, 1e-10, 15)
    h = headline_intervals(_records(spread, 3.0 * spread))
    assert h.dopt_ratio_interval == pytest.approx((3.0, 3.0))


def test_a_parameter_that_never_settles_counts_as_the_whole_flight():
    """Planned settling after the last sample: its sum is six whole flights."""
    planned = np.full(4, 1e-12)
    records = _records(planned, 2 * planned, settle=(99.0, 5.0))
    h = headline_intervals(records)
    assert h.convergence_reduction == pytest.approx(1.0 - T[-1] / 5.0)


def test_no_interval_without_two_paired_experiments():
    """One experiment, or records without random flights, give no interval."""
    assert headline_intervals(_records(np.array([1e-12]), np.array([3e-12]))) is None
    only_planned = [{"truth": TRUTH, "flights": [_flight("dopt", 1e-12, 1.0)]}] * 3
    assert headline_intervals(only_planned) is None


def test_headline_figures_of_arrays():
    """The figures of explicit arrays: median ratio and summed-time reduction."""
    ratios = {"dopt": np.ones((3, T.size, 6)), "random": np.ones((3, T.size, 6))}
    ratios["random"][:, :20] = 1.2  # settles at 2.0 s; planned at 0 s
    out = headline_figures(T, {"dopt": np.array([1.0, 2.0, 9.0]),
                               "random": np.array([3.0, 4.0, 5.0])}, ratios)
    assert out == pytest.approx([2.0, 1.0])


def test_saturating_flights_counts_the_last_iteration_over_the_threshold():
    """A flight counts when its last iteration saturated on more than 5 % of the ticks."""
    records = [
        {"flights": [_flight("dopt", 1.0, 1.0, 0, 0.50), _flight("dopt", 1.0, 1.0, 1, 0.01),
                     _flight("random", 1.0, 1.0, 0, 0.06)]},
        {"flights": [_flight("dopt", 1.0, 1.0, 0, 0.051), _flight("random", 1.0, 1.0, 0)]},
    ]
    assert saturating_flights(records) == {"dopt": (1, 2), "random": (1, 1)}


def test_off_path_flights_count_the_last_iteration_over_half_a_metre():
    """A flight is off its path when its last iteration tracked more than 0.5 m RMS off;
    flights recorded without a tracking RMS are left out."""
    records = [
        {"flights": [_flight("dopt", 1.0, 1.0, 0, tracking=3.0),
                     _flight("dopt", 1.0, 1.0, 1, tracking=0.01),
                     _flight("random", 1.0, 1.0, 0, tracking=0.51)]},
        {"flights": [_flight("dopt", 1.0, 1.0, 0, tracking=14.0),
                     _flight("random", 1.0, 1.0, 0)]},
    ]
    assert off_path_flights(records) == {"dopt": (1, 2), "random": (1, 1)}
    assert off_path_flights(records, threshold=1.0) == {"dopt": (1, 2), "random": (0, 1)}
