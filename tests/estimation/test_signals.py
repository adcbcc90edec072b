"""The signals of a flight: the smoother the diagnosis shares, and the log's measured noise."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.discrepancy import residuals
from mavsysid.estimation import signals
from mavsysid.estimation.balance import rows
from mavsysid.estimation.filter.guard import (
    NOISE_TOLERANCE,
    measured_pose_noise,
    pose_sigma,
)
from mavsysid.estimation.flight import FlightData
from mavsysid.vehicle.rotation import quat_exp, quat_multiply
from scipy.ndimage import uniform_filter1d


def test_discrepancy_uses_the_estimation_law():
    """The diagnosis' smoother and model are the estimator's objects, not copies."""
    assert residuals.smooth_pose is signals.smooth_pose
    assert residuals.model_accelerations is rows.model_accelerations
    assert residuals.SmootherSettings is signals.SmootherSettings


def _pose(seed: int, sigma_p: float, sigma_a: float, n: int = 3000, dt: float = 0.01
          ) -> FlightData:
    """A smooth figure-eight with white pose noise of known σ (seeded)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    p = np.column_stack([np.sin(0.7 * t), np.sin(1.4 * t), 1.0 + 0.2 * np.cos(0.5 * t)])
    angles = np.column_stack([0.2 * np.sin(1.1 * t), 0.15 * np.cos(0.9 * t), 0.3 * t])
    # Body-frame rotation noise of σ_a per axis on top of the motion.
    q = quat_multiply(quat_exp(angles), quat_exp(rng.normal(0.0, sigma_a, angles.shape)))
    p = p + rng.normal(0.0, sigma_p, p.shape)
    return FlightData(t, p, q, np.full((n, 4), 1000.0), "noise.csv")


@pytest.mark.parametrize(("seed", "sigma_p", "sigma_a"), [(0, 5e-4, 1e-3), (1, 5e-3, 1e-2),
                                                          (2, 2e-2, 3e-3)])
def test_measured_noise_matches_the_injected_noise(seed, sigma_p, sigma_a):
    position, attitude = measured_pose_noise(_pose(seed, sigma_p, sigma_a))
    assert position == pytest.approx(sigma_p, rel=0.1)
    assert attitude == pytest.approx(sigma_a, rel=0.1)


@pytest.mark.parametrize("seed", [3, 4])
def test_smoothed_pose_is_floored_at_the_assumed_sigma(seed):
    """A smoothed (on-board estimator) pose hides its noise: the assumed σ is the floor."""
    flight = _pose(seed, 5e-3, 1e-2)
    smooth = FlightData(flight.t, uniform_filter1d(flight.position, 25, axis=0),
                        flight.quaternion, flight.rotor_speeds, "smooth.csv")
    assert measured_pose_noise(smooth)[0] < 0.5 * 5e-3
    (used_p, _), _ = pose_sigma(smooth, (5e-3, 1e-2))
    assert used_p == 5e-3


def test_noise_matching_the_assumption_changes_nothing():
    """Within `NOISE_TOLERANCE` of the assumed σ the assumption stands, with no note."""
    flight = _pose(5, 5e-4, 1.7e-3)
    assumed = (5e-4, 1.7e-3)
    assert pose_sigma(flight, assumed) == (assumed, None)
    noisy = _pose(6, 3 * NOISE_TOLERANCE * 5e-4, 1.7e-3)
    (used_p, used_a), note = pose_sigma(noisy, assumed)
    assert used_p == pytest.approx(3 * NOISE_TOLERANCE * 5e-4, rel=0.1)
    assert used_a == assumed[1]
    assert note is not None and "measured from the pose" in note


@pytest.mark.parametrize("taps", [5, 63, 65, 151])
@pytest.mark.parametrize("shape", [(3000,), (3000, 4)])
def test_smoother_filter_is_the_zero_padded_convolution(taps, shape):
    """Direct or by FFT overlap-add, the filter is np.convolve(mode="same") per column."""
    from mavsysid.estimation.signals import convolve_columns

    rng = np.random.default_rng(taps)
    x, kernel = rng.standard_normal(shape), rng.standard_normal(taps)
    columns = x.reshape(shape[0], -1)
    want = np.column_stack([np.convolve(c, kernel, mode="same") for c in columns.T])
    np.testing.assert_allclose(convolve_columns(x, kernel).reshape(shape[0], -1), want, atol=1e-12)
