"""One equation-error fit of a flight: band, window and rotor-to-pose offset chosen from the
flight, then the regressions.

1. **Band** (`choose_band`, `choose_lowpass`). A torque balance ω̇ = J⁻¹ τ(n) holds only
   where both sides measure the same thing: below some frequency the rotor torque of a
   real flight is dominated by what the rigid-body model lacks or a controller cancels
   (trim imbalance, slow aerodynamic moments, a centre of gravity off the rotors'
   centre); above some frequency the pose's second derivative is noise and the rotor
   speeds' sensing lags. Where it holds the two are coherent: the band is the contiguous
   one around the coherence peak where γ² ≥ `MIN_COHERENCE` = 0.9 (pose smoothed with the
   short `PILOT_WINDOW`), roll/pitch and yaw apart, and the force rows get the low-pass
   where the vertical force is coherent with the thrust. γ² ≥ 0.9 keeps the forward and
   reverse slopes (Frisch's bounds) within about 10 % of each other. Nothing here is
   tuned to a vehicle.
2. **Window** (`smoother_window`): the longest Savitzky–Golay window that passes the
   highest band; both sides go through it and through the band-pass.
3. **Offset** (`scan_delay`). A pose from an on-board estimator, a motion-capture link or
   a logger's buffering reaches the log later than the rotor speeds it results from; a
   few milliseconds bias the inertia as much as a wrong window does. δ minimises the
   band-passed torque residual over a grid of ±`MAX_DELAY`, refined by a parabola.
4. **Regressions** (`regress`): the force rows give c_T and c_T c_D, the torque rows the
   ratios, with the reverse (Frisch) value of each main coefficient.

Rows are thinned to about `ROWS_PER_PERIOD` per period of the highest frequency kept:
the filtered rows carry nothing faster.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from mavsysid.estimation.balance.regression import LinearFit, fit_rows, reverse_coefficient
from mavsysid.estimation.balance.rows import (
    FORCE_COEFFICIENTS,
    ROTOR_FORCE_COLUMNS,
    ROTOR_TORQUE_COLUMNS,
    TORQUE_AXIS,
    TORQUE_COEFFICIENTS,
    BalanceBuilder,
    BalanceRows,
    builder_for,
)
from mavsysid.estimation.results import MAX_RELATIVE_SIGMA, Band, FitChoices
from mavsysid.estimation.signals import (
    Segment,
    savgol_kernel,
)
from mavsysid.vehicle.config import VehicleConfig
from scipy.signal import coherence, freqz

__all__ = [
    "MAIN_COLUMNS",
    "MAX_DELAY",
    "MIN_COHERENCE",
    "PILOT_WINDOW",
    "SIGNAL_COHERENCE",
    "BalanceFit",
    "balance_rows_for",
    "choose_band",
    "choose_fit",
    "choose_lowpass",
    "delay_sigma",
    "fit_balance",
    "regress",
    "scan_delay",
    "smoother_cutoff",
    "smoother_window",
    "welch_length",
]


#: γ² at or above which the rotors are taken to explain the motion (module docstring).
MIN_COHERENCE = 0.9
#: γ² of a signal-to-noise ratio of 1 (γ² = SNR / (1 + SNR)): `choose_lowpass`.
SIGNAL_COHERENCE = 0.5
#: Gain of the smoother at the band's top that counts as passing it.
PASS_GAIN = 0.9


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


#: Largest |δ| searched, s: on-board estimators delay their pose by up to about 0.1 s.
MAX_DELAY = 0.1
#: Coarsest grid step, s.
GRID_STEP = 0.002


def scan_delay(objective: Callable[[float], float], dt: float,
               max_delay: float = MAX_DELAY) -> tuple[float, np.ndarray, np.ndarray]:
    """The δ minimising ``objective`` over a grid, refined by a parabola.

    Parameters
    ----------
    objective : callable
        δ (s) → normalised residual (smaller is better; NaN where it cannot be formed).
    dt : float
        Sample interval, s (the grid step is at least this).
    max_delay : float
        Half-width of the grid, s.

    Returns
    -------
    delay : float
        s.
    grid, values : ndarray
        The grid (s) and the objective on it.
    """
    step = max(GRID_STEP, dt)
    grid = np.arange(-max_delay, max_delay + 0.5 * step, step)
    values = np.array([objective(float(d)) for d in grid])
    finite = np.isfinite(values)
    if not finite.any():
        return 0.0, grid, values
    i = int(np.nanargmin(np.where(finite, values, np.inf)))
    if 0 < i < len(grid) - 1 and np.all(finite[i - 1:i + 2]):
        a, b, c = values[i - 1:i + 2]
        curvature = a - 2.0 * b + c
        if curvature > 0.0:
            return float(grid[i] + 0.5 * step * (a - c) / curvature), grid, values
    return float(grid[i]), grid, values


#: Pilot Savitzky–Golay window for the coherence, s: passes attitude dynamics up to about
#: 30 Hz (gain 0.9), beyond any multirotor's attitude loop.
PILOT_WINDOW = 0.025
#: Filtered rows kept per period of the highest frequency passed.
ROWS_PER_PERIOD = 8
#: Main (physical) columns with a reverse value, and the rows' axes of each: torque
#: c_T/j_x, c_T/j_y, c_M/j_z. The force rows have none: their regressor, the thrust, is
#: measured to a fraction of a per cent (the rotor speeds), so the errors are on the
#: measured side, where least squares takes them.
MAIN_COLUMNS = {"force": (), "torque": ((0, (0,)), (3, (1,)), (6, (2,)))}


@dataclass(frozen=True)
class BalanceFit:
    """The regressions of one fit and the choices they were made with.

    Attributes
    ----------
    choices : FitChoices
    force, torque : LinearFit
        Coefficients of `FORCE_COEFFICIENTS` and `TORQUE_COEFFICIENTS`.
    reverse : dict
        ``{"force": {column: value}, "torque": {column: value}}``, the Frisch reverse
        values of the main columns.
    """

    choices: FitChoices
    force: LinearFit
    torque: LinearFit
    reverse: dict


def _stride(choices: FitChoices, dt: float) -> int:
    top = max([b.high for b in (choices.roll_pitch, choices.yaw, choices.force)
               if b is not None]
              + [smoother_cutoff(choices.window, dt)])
    return max(1, int(1.0 / (ROWS_PER_PERIOD * top * dt)))


def _dead_axes(rows: BalanceRows, choices: FitChoices) -> BalanceRows:
    """Zero the torque axes without a band, and the columns that act on them."""
    dead = [a for a, band in ((0, choices.roll_pitch), (1, choices.roll_pitch),
                              (2, choices.yaw)) if band is None]
    if not dead:
        return rows
    torque, cols = rows.torque.copy(), rows.torque_columns.copy()
    torque[:, dead] = 0.0
    cols[:, dead, :] = 0.0
    cols[:, :, [j for j, a in enumerate(TORQUE_AXIS) if a in dead]] = 0.0
    return BalanceRows(rows.t, rows.force, rows.force_columns, torque, cols)


def balance_rows_for(builders: list[BalanceBuilder], choices: FitChoices,
                     roll_pitch: Band | None = None, yaw: Band | None = None,
                     force: Band | None = None) -> list[BalanceRows]:
    """Thinned rows of every segment at ``choices`` (bands overridable), dead axes zeroed."""
    rp = roll_pitch or choices.roll_pitch
    yw = yaw or choices.yaw
    fc = force or choices.force
    out = []
    for b in builders:
        rows = b.rows(choices.delay, choices.c_d, rp, yw, fc,
                      drag_linear=choices.drag_linear, drag_c_d=choices.drag_c_d)
        rows = rows.rows(slice(None, None, _stride(choices, b.dt)))
        if len(rows) > 4:
            out.append(_dead_axes(rows, choices))
    return out


#: Highest band frequency per rotor-speed sample rate: the rotor speeds are interpolated
#: linearly between their samples, which passes a quarter of their rate at 0.9 of its
#: amplitude (sinc²) and a half not at all; the model's side above it is attenuated, the
#: measured side is not, and the coefficients would take the difference.
ROTOR_BAND_FRACTION = 0.15


def _pilot_bands(segments: list[Segment], config: VehicleConfig, c_d: float
                 ) -> tuple[Band | None, Band | None, Band | None]:
    """Roll/pitch, yaw and force bands from the pilot-smoothed rows (coherence)."""
    rows = [builder_for(s, config, PILOT_WINDOW).rows(0.0, c_d, magnitude=False)
            for s in segments]
    rows = [r for r in rows if len(r) > 0]
    if not rows:
        return None, None, None
    dt = segments[0].dt
    f_max = min(smoother_cutoff(PILOT_WINDOW, dt, 0.9),
                min(ROTOR_BAND_FRACTION / s.rotor_step for s in segments))
    torque = np.concatenate([r.torque for r in rows])
    cols = np.concatenate([r.torque_columns for r in rows])
    roll_pitch = choose_band(torque[:, :2], np.column_stack([cols[:, 0, 0], cols[:, 1, 3]]),
                             dt, f_max)
    yaw = choose_band(torque[:, 2], cols[:, 2, 6], dt, f_max)
    force = choose_lowpass(np.concatenate([r.force[:, 2] for r in rows]),
                           np.concatenate([r.force_columns[:, 2, 0] for r in rows]), dt, f_max)
    return roll_pitch, yaw, force


def _shifted(rows: BalanceRows, delay: float, stride: int) -> BalanceRows:
    """``rows`` (made at δ = 0) with the rotor columns taken at t − ``delay``, thinned.

    Every step from rotor speeds to a column is linear and time-invariant except the
    rotation to the body frame, which turns by at most a few hundredths of a radian in
    `MAX_DELAY`: shifting the finished columns is the scan's cheap stand-in for building
    them at each δ. Rows within `MAX_DELAY` of either end are dropped.
    """
    t = rows.t
    keep = np.flatnonzero((t >= t[0] + MAX_DELAY) & (t <= t[-1] - MAX_DELAY))[::stride]
    ts = t[keep] - delay

    def shift(x: np.ndarray) -> np.ndarray:
        flat = x.reshape(len(t), -1)
        out = np.column_stack([np.interp(ts, t, flat[:, j]) for j in range(flat.shape[1])])
        return out.reshape((len(keep),) + x.shape[1:])

    # The nuisance quantities' columns (after the model's) are taken as the rotors' too.
    torque_cols = rows.torque_columns[keep].copy()
    rotor = [*ROTOR_TORQUE_COLUMNS, *range(len(TORQUE_COEFFICIENTS), torque_cols.shape[2])]
    torque_cols[:, :, rotor] = shift(rows.torque_columns[:, :, rotor])
    force_cols = rows.force_columns[keep].copy()
    rotor = [*ROTOR_FORCE_COLUMNS, *range(len(FORCE_COEFFICIENTS), force_cols.shape[2])]
    force_cols[:, :, rotor] = shift(rows.force_columns[:, :, rotor])
    return BalanceRows(t[keep], rows.force[keep], force_cols, rows.torque[keep], torque_cols)


def _torque_objective(rows: list[BalanceRows], delay: float, stride: int) -> float:
    """Σ over the torque axes with a band of the residual's share of the measured power."""
    shifted = [_shifted(r, delay, stride) for r in rows]
    shifted = [r for r in shifted if len(r) > 4]
    if not shifted:
        return float("nan")
    fit = fit_rows([r.torque for r in shifted], [r.torque_columns for r in shifted],
                   covariance=False)
    power = np.mean(np.concatenate([r.torque for r in shifted]) ** 2, axis=0)
    live = power > 0.0
    return float(np.sum(fit.residual_rms[live] ** 2 / power[live]))


def choose_fit(segments: list[Segment], config: VehicleConfig, c_d: float
               ) -> tuple[FitChoices, list[BalanceBuilder]]:
    """Band, window and offset of ``segments`` (module docstring, steps 1–3).

    Parameters
    ----------
    segments : list of Segment
    config : VehicleConfig
    c_d : float
        c_D for the rotor drag's moments in the rows, s/m.
    """
    roll_pitch, yaw, force = _pilot_bands(segments, config, c_d)
    bands = [b for b in (roll_pitch, yaw, force) if b is not None]
    dt = segments[0].dt
    window = smoother_window(max(b.high for b in bands), dt) if bands else PILOT_WINDOW
    # A stretch shorter than two windows has no sample the smoother reaches from both sides.
    builders = [builder_for(s, config, window) for s in segments
                if s.t[-1] - s.t[0] >= 2.0 * window + 4.0 * s.dt]
    if not builders:
        window = PILOT_WINDOW
        builders = [builder_for(s, config, window) for s in segments]
    choices = FitChoices(window, roll_pitch, yaw, 0.0, c_d, force)
    if roll_pitch is not None or yaw is not None:
        rows = [_dead_axes(b.rows(0.0, c_d, roll_pitch, yaw, force), choices) for b in builders]
        rows = [r for r in rows if len(r) > 0]
        stride = _stride(choices, dt)
        delay, _, _ = scan_delay(lambda d: _torque_objective(rows, d, stride), dt)
        choices = replace(choices, delay=delay)
    return choices, builders


def regress(rows: list[BalanceRows]) -> tuple[LinearFit, LinearFit, dict]:
    """The force and torque fits of ``rows`` and the reverse values of the main columns."""
    y_f, X_f = [r.force for r in rows], [r.force_columns for r in rows]
    y_m, X_m = [r.torque for r in rows], [r.torque_columns for r in rows]
    force, torque = fit_rows(y_f, X_f), fit_rows(y_m, X_m)
    reverse = {"force": {}, "torque": {}}
    for name, fit, y, X in (("force", force, y_f, X_f), ("torque", torque, y_m, X_m)):
        for column, axes in MAIN_COLUMNS[name]:
            if np.isfinite(fit.covariance[column, column]):
                reverse[name][column] = reverse_coefficient(y, X, column, axes, fit.weights)
    return force, torque, reverse


def fit_balance(segments: list[Segment], config: VehicleConfig, c_d: float
                ) -> tuple[BalanceFit, list[BalanceBuilder]]:
    """Choose band, window and offset, then fit (module docstring).

    Parameters
    ----------
    segments : list of Segment
        At least one.
    config : VehicleConfig
    c_d : float
        Prior c_D, s/m: for the rotor drag's moments until the force rows give their own.

    Returns
    -------
    BalanceFit, list of BalanceBuilder
        The fit, and the builders (one per segment) for further rows at its window.
    """
    choices, builders = choose_fit(segments, config, c_d)
    force, torque, reverse = regress(balance_rows_for(builders, choices))
    b, sigma = force.coefficients, force.sigma
    fitted_c_d, fitted_linear = b[1] / b[0], b[2] / b[0]
    # The rows' drag moments take the fitted c_D only where the flight separates it from
    # the linear drag; the thrust row's magnitude takes the drag the fit sees, split or not.
    separated = np.isfinite(sigma[1]) and sigma[1] <= MAX_RELATIVE_SIGMA * abs(b[1])
    if np.isfinite(fitted_c_d) and np.isfinite(fitted_linear):
        new_c_d = float(fitted_c_d) if separated and fitted_c_d > 0.0 else c_d
        choices = replace(choices, c_d=new_c_d, drag_c_d=float(fitted_c_d),
                          drag_linear=float(fitted_linear))
        force, torque, reverse = regress(balance_rows_for(builders, choices))
    return BalanceFit(choices, force, torque, reverse), builders


def delay_sigma(fit: BalanceFit, builders: list[BalanceBuilder]) -> float:
    """σ of δ: the torque residual regressed on the model's derivative in δ (Newey–West).

    Parameters
    ----------
    fit : BalanceFit
        The fit at its chosen δ.
    builders : list of BalanceBuilder
        Its segments' builders (`fit_balance`), for the rows at δ ± one sample.
    """
    c = fit.choices
    h = builders[0].dt
    b = fit.torque.coefficients
    rows = balance_rows_for(builders, c)
    plus, minus = (balance_rows_for(builders, replace(c, delay=c.delay + s)) for s in (h, -h))
    if not (len(rows) == len(plus) == len(minus)) or not rows:
        return float("nan")
    y = [r.torque - r.torque_columns @ b for r in rows]
    X = [((p.torque_columns - m.torque_columns) @ b / (2 * h))[:, :, None]
         for p, m in zip(plus, minus, strict=True)]
    if any(len(x) != len(e) for x, e in zip(X, y, strict=True)):
        return float("nan")
    try:
        return float(fit_rows(y, X).sigma[0])
    except np.linalg.LinAlgError:
        return float("nan")
