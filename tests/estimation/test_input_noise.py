"""Slow rotor-speed inputs: interpolation, the uncertainty it leaves, and the estimate's σ."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import EstimatorSettings, estimate_parameters
from mavsysid.estimation.flight import InputSamples
from mavsysid.vehicle.config import load_vehicle


def _smooth_speeds(t: np.ndarray, seed: int) -> np.ndarray:
    """Two rotors' speeds, rad/s: 500 rad/s plus sinusoids of 0.3–1.5 Hz, random phases."""
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.3, 1.5, (2, 4))
    phase = rng.uniform(0.0, 2.0 * np.pi, (2, 4))
    waves = 20.0 * np.sin(2.0 * np.pi * freq[None] * t[:, None, None] + phase[None])
    return 500.0 + waves.sum(axis=2)


def test_density_grows_with_the_sample_interval_and_is_zero_at_samples() -> None:
    t = np.arange(0.0, 20.0, 0.005)
    fast_t, slow_t = t[::4], t[::50]
    fast = InputSamples(((fast_t, _smooth_speeds(fast_t, 1)),)).density(t)
    slow = InputSamples(((slow_t, _smooth_speeds(slow_t, 1)),)).density(t)
    trace = np.einsum("nii->n", slow)
    assert np.einsum("nii->n", fast).mean() * 100.0 < trace.mean()
    assert np.all(trace[::50] == 0.0)  # measured, not interpolated
    assert np.all(np.linalg.eigvalsh(slow) >= -1e-9)


def test_curvature_correction_beats_a_straight_line() -> None:
    t = np.arange(0.0, 20.001, 0.005)  # ends on a sample: no extrapolation
    truth = _smooth_speeds(t, 2)
    slow_t = t[::50]
    corrected = InputSamples(((slow_t, truth[::50]),)).interpolate(t)
    line = np.column_stack([np.interp(t, slow_t, truth[::50, j]) for j in range(2)])
    assert np.sqrt(np.mean((corrected - truth) ** 2)) < 0.7 * np.sqrt(np.mean((line - truth) ** 2))
    np.testing.assert_array_equal(corrected[::50], truth[::50])


@pytest.mark.parametrize("seed", [3, 4])
def test_density_is_the_size_of_the_interpolation_error(seed: int) -> None:
    """S / h against the squared mean error over each interval of a straight line."""
    t = np.arange(0.0, 60.0, 0.005)
    truth = _smooth_speeds(t, seed)
    slow_t = t[::50]
    line = np.column_stack([np.interp(t, slow_t, truth[::50, j]) for j in range(2)])
    interval = np.minimum(np.arange(t.size) // 50, slow_t.size - 2)
    counts = np.bincount(interval)
    mean_error = np.column_stack([np.bincount(interval, (truth - line)[:, j]) / counts
                                  for j in range(2)])
    S = InputSamples(((slow_t, truth[::50]),)).density(t[25::50])  # mid-interval
    predicted = np.einsum("nii->ni", S) / 0.25
    ratio = np.mean(mean_error[1:-1] ** 2) / np.mean(predicted[1:-1])
    assert 0.3 < ratio < 1.5


@pytest.mark.slow
def test_slow_inputs_give_a_larger_sigma_that_still_covers_the_truth(simulate_flight) -> None:
    """One simulated flight, its rotor speeds at 200 Hz and at 4 Hz: same truth, honest σ."""
    config = load_vehicle("firefly")
    fast = simulate_flight(config, seed=3, duration=12.0, log_rate=200.0, control_rate=1000.0)
    fast = dataclasses.replace(fast, inputs=InputSamples(((fast.t, fast.rotor_speeds),)))
    samples = InputSamples(((fast.t[::50], fast.rotor_speeds[::50]),))
    slow = dataclasses.replace(fast, rotor_speeds=samples.interpolate(fast.t), inputs=samples)
    # The filter alone: the guard would widen σ where the balance disagrees, hiding what
    # the input noise does to the filter's own σ.
    settings = EstimatorSettings(refine=False, guard=False)
    truth = fast.true_theta
    results = {}
    for name, flight in (("fast", fast), ("slow", slow),
                         ("slow, inputs taken as exact", dataclasses.replace(slow, inputs=None))):
        estimate = estimate_parameters(flight, config, settings).filtered
        sigma = np.sqrt(np.diag(estimate.covariance))
        results[name] = sigma, np.abs(estimate.value - truth) / sigma
    (fast_sigma, fast_z), (slow_sigma, slow_z) = results["fast"], results["slow"]
    assert np.all(slow_sigma >= fast_sigma) and np.any(slow_sigma > 1.2 * fast_sigma)
    assert np.all(fast_z < 1.96) and np.all(slow_z < 1.96), results
    # Without the added uncertainty the same estimate claims a σ the error breaks.
    assert np.any(results["slow, inputs taken as exact"][1] > 3.0), results
