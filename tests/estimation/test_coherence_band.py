"""The band where a model explains a measurement, chosen from coherence; its filters."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.balance.choices import (
    PASS_GAIN,
    choose_band,
    choose_lowpass,
    smoother_window,
    welch_length,
)
from mavsysid.estimation.results import Band
from mavsysid.estimation.signals import savgol_kernel
from scipy.signal import butter, freqz, sosfiltfilt

DT = 0.002


def _coloured(seed: int, n: int, low: float, high: float) -> np.ndarray:
    """White noise band-passed to [low, high] Hz (low = 0: low-passed)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    if low > 0:
        sos = butter(4, [low, high], btype="bandpass", fs=1 / DT, output="sos")
    else:
        sos = butter(4, high, btype="lowpass", fs=1 / DT, output="sos")
    return sosfiltfilt(sos, x)


@pytest.mark.parametrize(("seed", "low", "high"), [(0, 3.0, 9.0), (1, 1.0, 4.0), (2, 6.0, 20.0)])
def test_band_is_where_the_model_explains_the_measurement(seed, low, high):
    """The chosen band sits inside the frequencies where y follows x, not outside them."""
    n = 60_000
    signal = _coloured(seed + 100, n, low, high)      # y's part explained by x ...
    x = signal + 0.1 * _coloured(seed, n, 0.0, 60.0)
    y = signal + 0.1 * _coloured(seed + 200, n, 0.0, 60.0)  # ... plus unexplained
    band = choose_band(y, x, DT, f_max=50.0)
    assert band is not None
    assert low - 1.5 <= band.low and band.high <= high + 1.5, band
    assert band.high - band.low >= 0.4 * (high - low), band
    assert band.peak_coherence >= 0.9


def test_no_band_without_coherence():
    """Unrelated signals give no band."""
    x = _coloured(3, 20_000, 0.0, 40.0)
    y = _coloured(4, 20_000, 0.0, 40.0)
    assert choose_band(y, x, DT, f_max=50.0) is None


def test_lowpass_stops_where_the_noise_takes_over():
    """The force low-pass keeps the low frequencies y shares with x and stops above them."""
    n = 60_000
    x = _coloured(5, n, 0.0, 3.0)
    y = x + 0.05 * np.random.default_rng(6).standard_normal(n)
    band = choose_lowpass(y, x, DT, f_max=50.0)
    assert band.low == 0.0
    assert 2.0 <= band.high <= 8.0, band


@pytest.mark.parametrize("f_pass", [2.0, 6.0, 15.0])
def test_smoother_window_is_the_longest_passing_the_band(f_pass):
    """The window's gain at f_pass is ≥ 0.9 and the next longer window's is below it."""
    window = smoother_window(f_pass, DT)
    w = round(window / DT)

    def gain(length: int) -> float:
        return abs(freqz(savgol_kernel(length, 3, 0, DT), worN=[f_pass], fs=1 / DT)[1][0])

    assert gain(w) >= PASS_GAIN
    assert gain(w + 2) < PASS_GAIN


def test_band_filter_passes_the_band_without_phase_and_cuts_outside():
    """A sinusoid inside the band comes through unshifted; one far outside does not."""
    t = np.arange(20_000) * DT
    band = Band(3.0, 9.0)
    inside = np.sin(2 * np.pi * 5.0 * t)
    outside = np.sin(2 * np.pi * 0.5 * t) + np.sin(2 * np.pi * 40.0 * t)
    mid = slice(2000, -2000)
    assert np.allclose(band.apply(inside, DT)[mid], inside[mid], atol=0.05)
    assert np.max(np.abs(band.apply(outside, DT)[mid])) < 0.1
    assert band.apply(np.column_stack([inside, outside]), DT).shape == (len(t), 2)


def test_welch_segments_give_at_least_fifteen_averages():
    """The segment is a power of two no longer than an eighth of the record."""
    for n in (3000, 26_000, 30_000):
        m = welch_length(n)
        assert m & (m - 1) == 0 and m <= n / 8 < 2 * m
