"""The clock offset between a motion-capture pose file and a flight log, by cross-correlation.

The two clocks share no timestamps, so the offset is found from the motion itself. When
the flight log has a pose of its own, both sides give the body angular-rate magnitude
|ω| (frame independent, so NED/FRD against ENU/FLU does not matter, and unaffected by a
position offset between the two world frames). When it has rotor speeds only, the motion
capture's specific force along the body z axis, e_z^B · (a − g), is correlated with Σ n²
(thrust ∝ n²). Each signal is resampled on its own uniform grid of the finer sample
period; the lag of the peak of their correlation, refined by a parabola through the
peak, gives the offset.
"""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.readers.checks import repair_samples
from mavsysid.estimation.readers.streams import LogStreams
from mavsysid.formats.parsed_log import Series
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.rotation import (
    interpolate_quaternions,
    quat_conjugate,
    quat_log,
    quat_multiply,
    quat_to_matrix,
)
from scipy.signal import correlate, correlation_lags, savgol_filter

from mavsysid.errors import LogFormatError

__all__ = ["MIN_CORRELATION", "estimate_time_offset"]

#: Below this peak correlation the offset is not trusted (an error asks for it instead).
MIN_CORRELATION = 0.3
# Differentiation spans, s: differentiated motion-capture noise would otherwise dominate.
_RATE_BASELINE = 0.05
_ACCELERATION_WINDOW = 0.2


def _period(t: np.ndarray) -> float:
    return float(np.median(np.diff(t)))


def _grid(t: np.ndarray, dt: float) -> np.ndarray:
    return t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)


def _rate_signal(t: np.ndarray, q: np.ndarray, dt: float) -> tuple[float, np.ndarray]:
    """|ω|, rad/s, on a uniform grid of step dt: (time of the first value, values).

    The attitude is resampled first and differenced over ±`_RATE_BASELINE`: a longer
    baseline divides the attitude noise by more than smoothing a one-step rate would.
    """
    grid = _grid(t, dt)
    qg = interpolate_quaternions(t, q, grid)
    h = max(1, round(_RATE_BASELINE / dt))
    if grid.shape[0] <= 2 * h:
        raise LogFormatError("too few attitude samples to find the clock offset")
    turn = quat_log(quat_multiply(quat_conjugate(qg[:-2 * h]), qg[2 * h:]))
    return float(grid[h]), np.linalg.norm(turn, axis=1) / (2 * h * dt)


def _specific_force_signal(t: np.ndarray, pose: np.ndarray, dt: float,
                           label: str) -> tuple[float, np.ndarray]:
    """e_z^B · (a − g), m/s², from motion capture, on a uniform grid of step dt."""
    grid = _grid(t, dt)
    p = np.column_stack([np.interp(grid, t, pose[:, i]) for i in range(3)])
    q = interpolate_quaternions(t, pose[:, 3:7], grid)
    window = max(5, 2 * round(_ACCELERATION_WINDOW / dt / 2) + 1)
    if window > grid.shape[0]:
        raise LogFormatError(f"{label}: too few samples to find its clock offset")
    a = savgol_filter(p, window, 3, deriv=2, delta=dt, axis=0)
    a[:, 2] += GRAVITY
    return float(grid[0]), np.sum(quat_to_matrix(q)[:, :, 2] * a, axis=1)


def _thrust_signal(rotors: tuple[Series, ...], dt: float) -> tuple[float, np.ndarray]:
    """Σ n², (rad/s)², over the span all rotor series cover, on a uniform grid of step dt."""
    clean = [repair_samples(s.t, s.values, "", s.label)[:2] for s in rotors]
    lo = max(t[0] for t, _ in clean)
    hi = min(t[-1] for t, _ in clean)
    grid = _grid(np.array([lo, hi]), dt)
    total = sum(np.interp(grid, t, v[:, j]) ** 2 for t, v in clean for j in range(v.shape[1]))
    return float(grid[0]), np.asarray(total)


def _normalised_correlation(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pearson correlation of a[n + ℓ] with b[n] over their overlap, for every lag ℓ.

    Means and variances are those of the overlapping parts: normalising by the whole
    signals instead biases the peak when one recording spans more of the motion.
    """
    a, b = a - a.mean(), b - b.mean()
    m, n = a.shape[0], b.shape[0]
    lags = correlation_lags(m, n, mode="full")
    start_b, stop_b = np.maximum(0, -lags), np.minimum(n, m - lags)
    count = stop_b - start_b
    cum_a, cum_aa = (np.concatenate([[0.0], np.cumsum(x)]) for x in (a, a * a))
    cum_b, cum_bb = (np.concatenate([[0.0], np.cumsum(x)]) for x in (b, b * b))
    s_a = cum_a[stop_b + lags] - cum_a[start_b + lags]
    s_aa = cum_aa[stop_b + lags] - cum_aa[start_b + lags]
    s_b, s_bb = cum_b[stop_b] - cum_b[start_b], cum_bb[stop_b] - cum_bb[start_b]
    s_ab = correlate(a, b, mode="full", method="fft")
    var = (s_aa - s_a**2 / count) * (s_bb - s_b**2 / count)
    r = (s_ab - s_a * s_b / count) / np.sqrt(np.maximum(var, 1e-300))
    return lags, r


def _best_lag(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Lag ℓ, in samples, maximising the correlation of a[n + ℓ] with b[n], and its peak."""
    lags, r = _normalised_correlation(a, b)
    overlap = np.minimum(b.shape[0], a.shape[0] - lags) - np.maximum(0, -lags)
    # Short overlaps correlate well by chance: require half the shorter recording.
    r = np.where(overlap >= 0.5 * min(a.shape[0], b.shape[0]), r, -np.inf)
    i = int(np.argmax(r))
    frac = 0.0
    if 0 < i < r.shape[0] - 1 and np.isfinite(r[i - 1]) and np.isfinite(r[i + 1]):
        curvature = r[i - 1] - 2.0 * r[i] + r[i + 1]
        if curvature < 0.0:
            frac = 0.5 * (r[i - 1] - r[i + 1]) / curvature
    return float(lags[i] + frac), float(r[i])


def estimate_time_offset(log: LogStreams, mocap: Series, label: str) -> tuple[float, str]:
    """Offset to add to motion-capture times to put them on the flight log's clock.

    Parameters
    ----------
    log : LogStreams
        The flight log: its pose if it has one, else its rotor speeds.
    mocap : Series
        Clean motion-capture pose (strictly increasing t, m = 7, ENU/FLU).
    label : str
        The pose file, for messages.

    Returns
    -------
    offset : float
        s, such that t_log = t_mocap + offset.
    how : str
        The signals correlated and the peak correlation, for the info line.

    Raises
    ------
    LogFormatError
        The peak correlation is below `MIN_CORRELATION`.
    """
    if log.pose is not None:
        t, pose, _ = repair_samples(log.pose.t, log.pose.values, "", log.pose.label)
        q = pose[:, 3:7] / np.linalg.norm(pose[:, 3:7], axis=1, keepdims=True)
        dt = min(_period(t), _period(mocap.t))
        start_a, a = _rate_signal(t, q, dt)
        start_b, b = _rate_signal(mocap.t, mocap.values[:, 3:7], dt)
        what = "body angular-rate magnitude"
    else:
        dt = min(min(_period(s.t) for s in log.rotors), _period(mocap.t))
        start_a, a = _thrust_signal(log.rotors, dt)
        start_b, b = _specific_force_signal(mocap.t, mocap.values, dt, label)
        what = "Σ n² against the motion capture's body-z specific force"
    lag, peak = _best_lag(a, b)
    if peak < MIN_CORRELATION:
        raise LogFormatError(
            f"{label}: cannot find its clock offset to {log.source}: the {what} correlate "
            f"at {peak:.2f} at best; give the time offset explicitly")
    offset = start_a - start_b + lag * dt
    return offset, f"cross-correlation of the {what}, peak {peak:.2f}"
