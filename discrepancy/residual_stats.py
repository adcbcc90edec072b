"""Statistics of a model's residual: size, whiteness, NIS and where it is large.

`mavsysid.discrepancy.diagnosis` reports the gap between model and measurement with these:
RMS and Ljung–Box p-value per axis, the EKF's NIS against its χ² band, and the time
windows and flight regimes (speed, tilt, yaw rate, thrust) where the residual is large.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.discrepancy.residuals import ResidualProblem, SmoothedPose
from mavsysid.vehicle.mav_model import collective_thrust
from scipy.stats import chi2
from statsmodels.stats.diagnostic import acorr_ljungbox

__all__ = [
    "NIS_BAND",
    "AxisStats",
    "Where",
    "axis_rms",
    "ljung_box",
    "nis_stats",
    "where_large",
]

#: χ²(6) 95 % band of the NIS of a consistent filter with 6 measurement dimensions.
NIS_BAND = (float(chi2.ppf(0.025, 6)), float(chi2.ppf(0.975, 6)))


@dataclass(frozen=True)
class AxisStats:
    """Residual statistics per axis (order `AXIS_NAMES`) on one set of samples.

    Attributes
    ----------
    rms : ndarray, shape (6,)
        m/s² (forces) and rad/s² (angular accelerations).
    ljung_box_p : ndarray, shape (6,)
        p-value of the Ljung–Box test (10 lags) on samples one correlation length
        (`ResidualProblem.block`: the smoother window, plus the interpolation's reach on
        a resampled log) apart.
    nis_mean : float or None
        Mean NIS of the EKF over these samples (None if not computed).
    nis_outside : float or None
        Fraction of the NIS outside its χ²(6) 95 % band.
    """

    rms: np.ndarray
    ljung_box_p: np.ndarray
    nis_mean: float | None = None
    nis_outside: float | None = None


@dataclass(frozen=True)
class Where:
    """Where the base model's residual is large or not white (training and held-out).

    Attributes
    ----------
    windows : tuple of (float, float, int, float)
        Time windows (start s, end s, worst axis, normalised RMS) with a residual more
        than twice the noise level, largest first (at most 5).
    regimes : dict
        ``{regime: {"bins": [lo, hi] edges…, "rms": [[6 values] per bin]}}`` for
        ``speed`` (m/s), ``tilt`` (rad), ``yaw_rate`` (rad/s), ``thrust`` (N), the
        normalised RMS per axis in each tercile of the regime variable.
    worst_regime : tuple of (str, str) or None
        The regime and tercile where the residual is largest (e.g. ("speed", "high")).
    ljung_box_p : ndarray, shape (6,)
        Whiteness of the base residual on the training data.
    noise : ndarray, shape (6,)
        The noise level used to normalise, per axis.
    """

    windows: tuple[tuple[float, float, int, float], ...]
    regimes: dict
    worst_regime: tuple[str, str] | None
    ljung_box_p: np.ndarray
    noise: np.ndarray


def ljung_box(r: np.ndarray, step: int) -> np.ndarray:
    """Ljung–Box p-value (10 lags, or fewer on short data) per axis of r[::step]."""
    x = r[::max(step, 1)]
    lags = max(1, min(10, len(x) // 5))
    out = np.empty(r.shape[1])
    for a in range(r.shape[1]):
        if len(x) < 8 or np.allclose(x[:, a], x[0, a]):
            out[a] = np.nan
            continue
        out[a] = float(acorr_ljungbox(x[:, a], lags=[lags])["lb_pvalue"].iloc[0])
    return out


def axis_rms(r: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(r**2, axis=0))


def nis_stats(nis: np.ndarray | None, rows: np.ndarray) -> tuple[float | None, float | None]:
    """Mean NIS over ``rows`` and the fraction outside `NIS_BAND` (None, None without NIS)."""
    if nis is None:
        return None, None
    x = nis[rows]
    x = x[np.isfinite(x)]
    outside = np.mean((x < NIS_BAND[0]) | (x > NIS_BAND[1]))
    return float(np.mean(x)), float(outside)


def where_large(problem: ResidualProblem, pose: SmoothedPose, r: np.ndarray, used: np.ndarray,
           noise: np.ndarray, train: np.ndarray, window: float) -> Where:
    """Where the residual ``r`` (N, 6) is large: time windows of length ``window`` s and
    terciles of the flight regimes, in units of ``noise`` (6,); whiteness on ``train``."""
    t = problem.flight.t
    z = r / noise
    windows = []
    for t0 in np.arange(t[used][0], t[used][-1] - 0.5 * window, window):
        m = used & (t >= t0) & (t < t0 + window)
        if m.sum() < 3:
            continue
        per_axis = axis_rms(z[m])
        total = float(np.sqrt(np.mean(per_axis**2)))
        if total > 2.0:
            windows.append((float(t0), float(t0 + window), int(np.argmax(per_axis)), total))
    windows.sort(key=lambda w: -w[3])
    n = problem.flight.rotor_speeds
    rates = pose.rates
    R = pose.rotation()
    variables = {
        "speed": np.linalg.norm(pose.velocity, axis=1),
        "tilt": np.arccos(np.clip(R[:, 2, 2], -1.0, 1.0)),
        "yaw_rate": np.abs(rates[:, 2]),
        "thrust": collective_thrust(problem.theta[0], n),
    }
    regimes: dict = {}
    worst, worst_value = None, -np.inf
    for name, v in variables.items():
        edges = np.quantile(v[used], [0.0, 1 / 3, 2 / 3, 1.0])
        rms_bins = []
        for i, label in enumerate(("low", "mid", "high")):
            m = used & (v >= edges[i]) & (v <= edges[i + 1])
            per_axis = axis_rms(z[m]) if m.any() else np.full(6, np.nan)
            rms_bins.append(per_axis)
            value = float(np.sqrt(np.nanmean(per_axis**2)))
            if value > worst_value:
                worst, worst_value = (name, label), value
        regimes[name] = {"edges": edges, "rms": np.array(rms_bins)}
    return Where(tuple(windows[:5]), regimes, worst,
                 ljung_box(r[train], problem.block), noise)
