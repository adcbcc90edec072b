"""The frequency band where the rotors explain the body's motion, chosen from the flight.

A torque balance ω̇ = J⁻¹ τ(n) holds only where both sides measure the same thing. Below
some frequency the rotor torque of a real flight is dominated by what the rigid-body model
lacks or what a controller cancels (trim imbalance of the rotors, slowly varying
aerodynamic moments, a centre of gravity off the rotors' centre), so it moves without the
body turning; above some frequency the pose's second derivative is noise, and the rotor
speeds' sensing lags. Where it holds, the two are coherent: the magnitude-squared
coherence γ²(f) of the measured ω̇ and the model torque (Welch) is close to 1.

`choose_band` takes the contiguous band around the coherence peak where γ² stays at or
above `MIN_COHERENCE` = 0.9. The threshold bounds the errors-in-variables ambiguity: in a
band, the slope of the measured side on the model and the inverse slope of the model on
the measured side differ by the factor 1/γ² (Frisch's bounds), so γ² ≥ 0.9 keeps the two
within about 10 % of each other, and the estimate's interval, which covers both
(`mavsysid.estimation.parameter_status`), within about ±5 %. (Tischler and Remple's
guideline for fitting a transfer function, γ² ≥ 0.6, leaves a factor 1.7 between them.)
Both sides of the balance are then filtered alike by a zero-phase Butterworth band-pass
(`Band.apply`), so nothing outside the band enters the fit, and the Savitzky–Golay
window is the longest that still passes the band (`smoother_window`). Nothing here is
tuned to a vehicle: a vehicle with other dynamics, noise or lags gets another band.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from mavsysid.estimation.equation_error import savgol_kernel
from scipy.signal import butter, coherence, freqz, sosfiltfilt

__all__ = ["MIN_COHERENCE", "SIGNAL_COHERENCE", "Band", "choose_band", "choose_lowpass",
           "smoother_cutoff", "smoother_window", "welch_length"]

#: γ² at or above which the rotors are taken to explain the motion (module docstring).
MIN_COHERENCE = 0.9
#: γ² of a signal-to-noise ratio of 1 (γ² = SNR / (1 + SNR)): `choose_lowpass`.
SIGNAL_COHERENCE = 0.5
#: Gain of the smoother at the band's top that counts as passing it.
PASS_GAIN = 0.9
#: Butterworth order of each side of the band-pass (doubled by the forward-backward pass).
FILTER_ORDER = 2


@dataclass(frozen=True)
class Band:
    """A frequency band [low, high], Hz, and the coherence found in it.

    ``low = 0`` is a low-pass. Attributes: ``low``, ``high``, ``peak`` (Hz of the highest
    coherence) and ``peak_coherence``, ``mean_coherence`` (γ² over the band).
    """

    low: float
    high: float
    peak: float = float("nan")
    peak_coherence: float = float("nan")
    mean_coherence: float = float("nan")

    @property
    def centre(self) -> float:
        """Geometric centre, Hz (the arithmetic one for a low-pass)."""
        return float(np.sqrt(self.low * self.high)) if self.low > 0 else 0.5 * self.high

    def halves(self) -> tuple[Band, Band]:
        """The band split at its centre."""
        c = self.centre
        return Band(self.low, c), Band(c, self.high)

    def apply(self, x: np.ndarray, dt: float) -> np.ndarray:
        """``x`` band-passed along axis 0 (zero phase), same shape.

        Parameters
        ----------
        x : ndarray, shape (N, ...)
        dt : float
            Sample interval, s.
        """
        sos = _sos(self.low, self.high, dt)
        shape = x.shape
        flat = np.asarray(x, float).reshape(shape[0], -1)
        return sosfiltfilt(sos, flat, axis=0).reshape(shape)

    def settle(self) -> float:
        """Time to cut off each end after filtering, s: one period of the lowest frequency."""
        return 1.0 / (self.low if self.low > 0 else self.high)


@lru_cache(maxsize=64)
def _sos(low: float, high: float, dt: float) -> np.ndarray:
    nyquist = 0.5 / dt
    high = min(high, 0.95 * nyquist)
    if low > 0:
        return butter(FILTER_ORDER, [low, high], btype="bandpass", fs=1.0 / dt, output="sos")
    return butter(FILTER_ORDER, high, btype="lowpass", fs=1.0 / dt, output="sos")


def welch_length(n: int) -> int:
    """Welch segment length: the longest power of 2 giving at least 15 averages (n/8)."""
    return int(2 ** int(np.floor(np.log2(max(n / 8, 16.0)))))


def _coherence(measured: np.ndarray, model: np.ndarray, dt: float
               ) -> tuple[np.ndarray, np.ndarray] | None:
    """Frequencies (Hz) and γ² averaged over the axes; None for too few samples."""
    measured = np.atleast_2d(np.asarray(measured, float).T).T
    model = np.atleast_2d(np.asarray(model, float).T).T
    nper = welch_length(measured.shape[0])
    if measured.shape[0] < 2 * nper:
        return None
    with np.errstate(divide="ignore", invalid="ignore"):  # a signal without power: γ² = 0
        f, gamma = coherence(measured, model, fs=1.0 / dt, nperseg=nper, axis=0)
    return f, np.nan_to_num(gamma.reshape(len(f), -1)).mean(axis=1)


def choose_band(measured: np.ndarray, model: np.ndarray, dt: float, f_max: float,
                min_coherence: float = MIN_COHERENCE) -> Band | None:
    """The contiguous band around the coherence peak with γ² ≥ ``min_coherence``.

    Parameters
    ----------
    measured, model : ndarray, shape (N, A) or (N,)
        The measured quantity and the model's main regressor, A axes (their coherences
        are averaged over the axes).
    dt : float
        Sample interval, s.
    f_max : float
        Highest frequency considered, Hz (where the pilot smoother still passes).
    min_coherence : float
        γ² threshold.

    Returns
    -------
    Band or None
        None when the coherence nowhere reaches the threshold.
    """
    found = _coherence(measured, model, dt)
    if found is None:
        return None
    f, gamma = found
    usable = (f >= 2.0 * f[1]) & (f <= f_max)
    if not usable.any():
        return None
    peak = int(np.argmax(np.where(usable, gamma, -1.0)))
    if gamma[peak] < min_coherence:
        return None
    lo = hi = peak
    while lo - 1 >= 0 and usable[lo - 1] and gamma[lo - 1] >= min_coherence:
        lo -= 1
    while hi + 1 < len(f) and usable[hi + 1] and gamma[hi + 1] >= min_coherence:
        hi += 1
    # The band reaches half a bin beyond its outer bins (a single bin is a band too).
    half = 0.5 * f[1]
    return Band(max(f[lo] - half, half), f[hi] + half, float(f[peak]), float(gamma[peak]),
                float(np.mean(gamma[lo:hi + 1])))


def choose_lowpass(measured: np.ndarray, model: np.ndarray, dt: float, f_max: float,
                   min_coherence: float = SIGNAL_COHERENCE) -> Band | None:
    """A low-pass up to where γ² first falls below ``min_coherence`` (from the lowest bin).

    For a balance whose information is at the lowest frequencies and whose regressor is
    measured cleanly (the force rows: thrust from the rotor speeds), frequencies where the
    measured side's noise outweighs the signal (γ² < 0.5, signal-to-noise below 1) add
    noise, not information. When even the lowest usable bin is below the threshold, the
    cut is that bin.

    Parameters
    ----------
    measured, model : ndarray, shape (N,) or (N, A)
    dt : float
        Sample interval, s.
    f_max : float
        Highest frequency considered, Hz.
    min_coherence : float

    Returns
    -------
    Band or None
        A low-pass (``low = 0``); None for too few samples.
    """
    found = _coherence(measured, model, dt)
    if found is None:
        return None
    f, gamma = found
    first = int(np.searchsorted(f, 2.0 * f[1]))
    top = first
    while top + 1 < len(f) and f[top + 1] <= f_max and gamma[top + 1] >= min_coherence \
            and gamma[top] >= min_coherence:
        top += 1
    return Band(0.0, float(f[top] + 0.5 * f[1]), float(f[first]), float(gamma[first]),
                float(np.mean(gamma[first:top + 1])))


def smoother_window(f_pass: float, dt: float, polyorder: int = 3) -> float:
    """The longest cubic Savitzky–Golay window, s, whose gain at ``f_pass`` is ≥ 0.9.

    Parameters
    ----------
    f_pass : float
        Highest frequency to pass, Hz.
    dt : float
        Sample interval, s.
    polyorder : int
    """
    best = polyorder + 2 + (polyorder + 1) % 2
    w = best
    while True:
        gain = abs(freqz(savgol_kernel(w, polyorder, 0, dt), worN=[f_pass], fs=1.0 / dt)[1][0])
        if gain < PASS_GAIN or w * dt > 10.0 / f_pass:
            return best * dt
        best, w = w, w + 2


def smoother_cutoff(window: float, dt: float, gain: float = 0.5, polyorder: int = 3) -> float:
    """The lowest frequency, Hz, at which a cubic Savitzky–Golay window's gain is ``gain``.

    Parameters
    ----------
    window : float
        s.
    dt : float
        Sample interval, s.
    gain : float
    polyorder : int
    """
    w = max(polyorder + 2, round(window / dt))
    w += 1 - w % 2
    f, h = freqz(savgol_kernel(w, polyorder, 0, dt), worN=2048, fs=1.0 / dt)
    below = np.flatnonzero(np.abs(h) < gain)
    return float(f[below[0]]) if below.size else float(f[-1])
