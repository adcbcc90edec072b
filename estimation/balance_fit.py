"""One equation-error fit of a flight: band, window, time offset, then the regressions.

Steps, all chosen from the flight itself:

1. **Band.** The pose is smoothed with a short pilot window (`PILOT_WINDOW`), and the
   coherence of the measured ω̇ with the rotor torque picks the roll/pitch band and, on
   its own, the yaw band (`mavsysid.estimation.coherence_band.choose_band`); that of the
   vertical force with the thrust picks the force rows' low-pass (`choose_lowpass`).
2. **Window.** The Savitzky–Golay window is the longest that passes the highest band
   (`smoother_window`); both sides go through it and through the band-pass.
3. **Offset.** δ minimises the band-passed torque residual
   (`mavsysid.estimation.time_offset.scan_delay`).
4. **Regressions.** The force rows give c_T and c_T c_D; the torque rows the ratios of
   `mavsysid.estimation.wrench_regressors.TORQUE_COEFFICIENTS`
   (`mavsysid.estimation.balance_regression.fit_rows`, Newey–West covariance), with the
   reverse (Frisch) value of each main coefficient.

Rows are thinned to about `ROWS_PER_PERIOD` per period of the highest frequency kept:
the filtered rows carry nothing faster, so denser rows add cost, not information.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from mavsysid.estimation.balance_regression import LinearFit, fit_rows, reverse_coefficient
from mavsysid.estimation.coherence_band import (
    Band,
    choose_band,
    choose_lowpass,
    smoother_cutoff,
    smoother_window,
)
from mavsysid.estimation.parameter_status import MAX_RELATIVE_SIGMA
from mavsysid.estimation.time_offset import MAX_DELAY, scan_delay
from mavsysid.estimation.uniform_pose import UniformSegment
from mavsysid.estimation.wrench_regressors import (
    ROTOR_FORCE_COLUMNS,
    ROTOR_TORQUE_COLUMNS,
    TORQUE_AXIS,
    BalanceBuilder,
    BalanceRows,
)
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["MAIN_COLUMNS", "PILOT_WINDOW", "BalanceFit", "FitChoices", "balance_rows_for",
           "choose_fit", "fit_balance", "regress"]

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
class FitChoices:
    """What the flight chose: window (s), bands (or None), offset δ (s), c_D for the rows.

    ``force`` is the force rows' low-pass (a `Band` with ``low = 0``); ``drag_linear``
    (k / c_T, s·rad/m) and ``drag_c_d`` (s/m) the fitted drag in the thrust row's
    magnitude (NaN: ``c_d``).
    """

    window: float
    roll_pitch: Band | None
    yaw: Band | None
    delay: float
    c_d: float
    force: Band | None = None
    drag_linear: float = 0.0
    drag_c_d: float = float("nan")


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


def _pilot_bands(segments: list[UniformSegment], config: VehicleConfig, c_d: float
                 ) -> tuple[Band | None, Band | None, Band | None]:
    """Roll/pitch, yaw and force bands from the pilot-smoothed rows (coherence)."""
    rows = [BalanceBuilder(s, config, PILOT_WINDOW).rows(0.0, c_d, magnitude=False)
            for s in segments]
    rows = [r for r in rows if len(r) > 0]
    if not rows:
        return None, None, None
    dt = segments[0].dt
    f_max = smoother_cutoff(PILOT_WINDOW, dt, 0.9)
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

    torque_cols = rows.torque_columns[keep].copy()
    rotor = list(ROTOR_TORQUE_COLUMNS)
    torque_cols[:, :, rotor] = shift(rows.torque_columns[:, :, rotor])
    force_cols = rows.force_columns[keep].copy()
    rotor = list(ROTOR_FORCE_COLUMNS)
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


def choose_fit(segments: list[UniformSegment], config: VehicleConfig, c_d: float
               ) -> tuple[FitChoices, list[BalanceBuilder]]:
    """Band, window and offset of ``segments`` (module docstring, steps 1–3).

    Parameters
    ----------
    segments : list of UniformSegment
    config : VehicleConfig
    c_d : float
        c_D for the rotor drag's moments in the rows, s/m.
    """
    roll_pitch, yaw, force = _pilot_bands(segments, config, c_d)
    bands = [b for b in (roll_pitch, yaw, force) if b is not None]
    dt = segments[0].dt
    window = smoother_window(max(b.high for b in bands), dt) if bands else PILOT_WINDOW
    # A stretch shorter than two windows has no sample the smoother reaches from both sides.
    builders = [BalanceBuilder(s, config, window) for s in segments
                if s.t[-1] - s.t[0] >= 2.0 * window + 4.0 * s.dt]
    if not builders:
        window = PILOT_WINDOW
        builders = [BalanceBuilder(s, config, window) for s in segments]
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


def fit_balance(segments: list[UniformSegment], config: VehicleConfig, c_d: float
                ) -> tuple[BalanceFit, list[BalanceBuilder]]:
    """Choose band, window and offset, then fit (module docstring).

    Parameters
    ----------
    segments : list of UniformSegment
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
