"""The pose's measurement noise, measured from the log itself.

Each coordinate is fitted by a local cubic (Savitzky–Golay over `NOISE_WINDOW` samples);
the residual of a local polynomial fit is the white part of the noise times
√(1 − c₀) (c₀ the fit's centre weight: the fit is a projection), and its robust scale
(1.4826 × MAD) ignores the odd outlier and manoeuvre. Attitude: the four quaternion
components (sign made continuous); a small rotation δ moves q by |δ|/2, so the per-axis
angle σ is 2 √(Σ σ_c² / 3).

An on-board estimator's pose is smoothed: its white residual collapses although its
error (lag, correlated drift) does not. So the measured σ never goes below the σ the
caller assumes for that pose source (the config's motion-capture σ, or the autopilot's):
`pose_sigma` takes the measured value only when it exceeds the assumed one clearly
(`NOISE_TOLERANCE`), so a log that confirms the assumption is processed exactly as before.
"""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.equation_error import savgol_kernel
from mavsysid.estimation.flight_data import FlightData
from mavsysid.vehicle.rotation import continuous_sign
from scipy.ndimage import convolve1d

__all__ = ["NOISE_TOLERANCE", "NOISE_WINDOW", "measured_pose_noise", "pose_sigma"]

#: Samples of the local cubic fit (odd).
NOISE_WINDOW = 9

#: The measured σ replaces the assumed one when larger by more than this factor.
NOISE_TOLERANCE = 1.5

_MAD_TO_SIGMA = 1.4826


def _white_sigma(x: np.ndarray) -> np.ndarray:
    """Robust σ of the white part of each column of x (N, k)."""
    c = savgol_kernel(NOISE_WINDOW, 3, 0, 1.0)
    e = (x - convolve1d(x, c, axis=0, mode="nearest"))[NOISE_WINDOW:-NOISE_WINDOW]
    mad = np.median(np.abs(e - np.median(e, axis=0)), axis=0)
    return _MAD_TO_SIGMA * mad / np.sqrt(1.0 - c[NOISE_WINDOW // 2])


def measured_pose_noise(flight: FlightData) -> tuple[float, float]:
    """White-noise σ of position (m) and attitude (rad, per axis) in the longest segment."""
    if len(flight.segment_starts) > 1:
        flight = flight.segment(flight.longest_segment())
    if len(flight) < 3 * NOISE_WINDOW:
        return 0.0, 0.0
    q = continuous_sign(flight.quaternion)
    position = float(np.median(_white_sigma(np.asarray(flight.position, float))))
    attitude = float(2.0 * np.sqrt(np.sum(_white_sigma(q) ** 2) / 3.0))
    return position, attitude


def pose_sigma(flight: FlightData, assumed: tuple[float, float]
               ) -> tuple[tuple[float, float], str | None]:
    """Measurement σ (m, rad) for the filter, and a note when the log changed it.

    Parameters
    ----------
    flight : FlightData
    assumed : tuple of 2 float
        σ assumed for the pose source (m, rad): the floor.
    """
    measured = measured_pose_noise(flight)
    used = tuple(m if m > NOISE_TOLERANCE * a else a
                 for m, a in zip(measured, assumed, strict=True))
    if used == tuple(assumed):
        return tuple(assumed), None  # type: ignore[return-value]
    return used, (  # type: ignore[return-value]
        f"measurement σ measured from the pose (local-cubic residual, robust): "
        f"{1000 * measured[0]:.2g} mm, {np.degrees(measured[1]):.2g}°; used "
        f"{1000 * used[0]:.2g} mm, {np.degrees(used[1]):.2g}° (floor: the assumed "
        f"{1000 * assumed[0]:.2g} mm, {np.degrees(assumed[1]):.2g}°)")
