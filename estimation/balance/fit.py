"""θ from the force and torque balance, per parameter, with the held-out check.

The equation-error estimate as an answer of its own (docs/estimation-real-flights.md):
the pose's fresh samples on a uniform grid; band, window and offset chosen from the flight
and the regressions (`mavsysid.estimation.balance.choices`); θ, its σ widened by errors in
the variables and by the disagreement of the flight's halves and the band's halves
(`mavsysid.estimation.balance.theta`); and a status per quantity: determined when its
widened σ is within `mavsysid.estimation.results.MAX_RELATIVE_SIGMA` of its value (a
nuisance quantity: a fourfold narrowing of its prior), else the prior's value and σ are
kept (`mavsysid.estimation.results.quantity_status`). `fit_wrench_balance` answers for
every parameter the flight determines; a flight it determines nothing of still gives its
data θ, the filter's equation-error reference
(`mavsysid.estimation.results.WrenchBalanceResult.with_prior`).

**Held-out check** (`predict_holdout`): the metric a researcher can check without the
truth (and the one data-driven multirotor models are compared by, e.g. NeuroBEM's force
and torque RMSE). The balance is fitted on the first part of the flight (band, window,
offset and θ all chosen there) and predicts the rest from its pose and rotor speeds; the
RMSE of the measured minus the predicted body specific force and angular acceleration is
compared with the prior θ's. A ratio below 1 is a model that predicts unseen data better
than the prior.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.balance.choices import (
    MAIN_COLUMNS,
    BalanceFit,
    balance_rows_for,
    delay_sigma,
    fit_balance,
    regress,
)
from mavsysid.estimation.balance.rows import (
    FORCE_COEFFICIENTS,
    BalanceBuilder,
    BalanceRows,
    builder_for,
)
from mavsysid.estimation.balance.theta import (
    coefficients_from_theta,
    errors_in_variables_sigma,
    split_widening,
    stack,
    stacked_covariance,
    theta_from_coefficients,
    unstack,
    widened_sigma,
    with_nuisance_prior,
)
from mavsysid.estimation.checks import check_rotor_balance
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import (
    COMBINATION_NAMES,
    MAX_RELATIVE_SIGMA,
    Band,
    DataTheta,
    FitChoices,
    HoldoutCheck,
    ParameterEstimate,
    WrenchBalanceResult,
    prior_from_config,
    quantity_status,
)
from mavsysid.estimation.signals import (
    ImuSegment,
    Segment,
    balance_segments,
    uniform_segments,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.parameters import C_D, C_M, C_T, INERTIA

from mavsysid.errors import JobFailedError

__all__ = ["SMOOTHING_WINDOW", "WrenchBalanceSettings", "WrenchComparison",
           "balance_coefficients", "compare_wrench", "fit_wrench_balance", "predict_holdout"]


def predict_holdout(segments: list[Segment], config: VehicleConfig,
                    choices: FitChoices, coefficients: np.ndarray,
                    prior_coefficients: np.ndarray) -> HoldoutCheck | None:
    """Predict the held-out segments with the training part's choices and coefficients.

    Parameters
    ----------
    segments : list of Segment
        The held-out part.
    config : VehicleConfig
    choices : FitChoices
        The training part's window, bands and offset.
    coefficients, prior_coefficients : ndarray, shape (P,)
        Stacked force and torque coefficients (`mavsysid.estimation.balance.theta.stack`)
        of the fitted model
        and of the prior.

    Returns
    -------
    HoldoutCheck or None
        None when no held-out rows remain after the smoother's edges.
    """
    builders = [builder_for(s, config, choices.window) for s in segments
                if len(s) > 4 * choices.window / s.dt]
    rows = balance_rows_for(builders, choices) if builders else []
    if not rows:
        return None
    measured = np.concatenate([np.hstack([r.force, r.torque]) for r in rows])

    def prediction(b: np.ndarray) -> np.ndarray:
        force, torque = unstack(b)
        return np.concatenate([np.hstack([r.force_columns @ force,
                                          r.torque_columns @ torque]) for r in rows])

    def rmse(b: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean((measured - prediction(b)) ** 2, axis=0))

    live = np.any(measured != 0.0, axis=0)
    nan = np.where(live, 1.0, np.nan)
    return HoldoutCheck(float(segments[0].t[0]), rmse(coefficients) * nan,
                        rmse(prior_coefficients) * nan, len(measured))


#: Stacked coefficients, and where the torque ones start.
TORQUE_START = len(FORCE_COEFFICIENTS)


@dataclass(frozen=True)
class WrenchBalanceSettings:
    """Choices of `fit_wrench_balance`.

    Attributes
    ----------
    min_segment : float
        Shortest gap-free stretch used, s.
    holdout_fraction : float
        Share of the flight (its end) held out for validation; 0 skips the check.
    max_relative_sigma : float
        Largest widened σ / |θ| of a determined parameter.
    """

    min_segment: float = 2.0
    holdout_fraction: float = 0.3
    max_relative_sigma: float = MAX_RELATIVE_SIGMA


def _theta(fit_force: np.ndarray, fit_torque: np.ndarray, cov_force: np.ndarray,
           cov_torque: np.ndarray, prior: ParameterEstimate) -> DataTheta:
    """θ of a force and a torque fit, combined with the sensors' priors."""
    data = theta_from_coefficients(stack(fit_force, fit_torque),
                                   stacked_covariance(cov_force, cov_torque))
    return with_nuisance_prior(data, prior.value, prior.sigma)


def _fit_theta(fit: BalanceFit, prior: ParameterEstimate) -> DataTheta:
    return _theta(fit.force.coefficients, fit.torque.coefficients, fit.force.covariance,
                  fit.torque.covariance, prior)


def _eiv_sigma(fit: BalanceFit, base: DataTheta, prior: ParameterEstimate
               ) -> tuple[np.ndarray, np.ndarray]:
    """σ of θ and of the combinations from each main column's reverse value."""
    parts, combos = [], []
    covariance = stacked_covariance(fit.force.covariance, fit.torque.covariance)
    for name, offset in (("force", 0), ("torque", TORQUE_START)):
        for column, _ in MAIN_COLUMNS[name]:
            reverse = fit.reverse[name].get(column)
            if reverse is None or not np.isfinite(reverse):
                continue
            b = stack(fit.force.coefficients, fit.torque.coefficients)
            b[offset + column] = reverse
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                other = with_nuisance_prior(theta_from_coefficients(b, covariance),
                                            prior.value, prior.sigma)
            parts.append(errors_in_variables_sigma(base.value, other.value))
            combos.append(errors_in_variables_sigma(base.combinations, other.combinations))
    if not parts:
        return np.zeros_like(base.value), np.zeros_like(base.combinations)
    return widened_sigma(parts), widened_sigma(combos)


def _split_sigma(rows_a: list[BalanceRows], rows_b: list[BalanceRows],
                 prior: ParameterEstimate) -> tuple[np.ndarray, np.ndarray]:
    """σ added by two parts of the rows that disagree beyond their own σ (the prior's
    quantities, then the combinations)."""
    try:
        fits = [regress(rows) for rows in (rows_a, rows_b)]
    except np.linalg.LinAlgError:
        return np.zeros(prior.value.size), np.zeros(len(COMBINATION_NAMES))
    a, b = (_theta(f.coefficients, m.coefficients, f.covariance, m.covariance, prior)
            for f, m, _ in fits)
    return (split_widening(a.value, a.sigma, b.value, b.sigma),
            split_widening(a.combinations, a.combination_sigma, b.combinations,
                           b.combination_sigma))


def _thrust_row_sigma(fit: BalanceFit, rows: list[BalanceRows], theta: np.ndarray
                      ) -> np.ndarray:
    """σ of θ from the thrust row's second-order bias, bounded by the noise across thrust.

    The thrust row compares magnitudes (`mavsysid.estimation.balance.rows`): noise
    perpendicular to the thrust lengthens the measured |f| by σ_⊥² / (2 |f|), and an
    attitude error would shorten its z component by as much. The horizontal rows'
    residuals measure σ_⊥² (pose noise, attitude error times g, unmodelled horizontal
    force), so ±σ_⊥² / (2 |f|²) of c_T, and of everything scaled by c_T (c_M and J), is
    a bias the sandwich cannot see.
    """
    magnitude = float(np.mean(np.concatenate([r.force[:, 2] for r in rows]))) if rows else 0.0
    if not magnitude > 0.0:
        return np.zeros_like(theta)
    relative = float(np.sum(fit.force.residual_rms[:2] ** 2)) / (2.0 * magnitude**2)
    scaled = np.zeros(theta.size)
    scaled[[C_T, C_M]] = 1.0
    scaled[INERTIA] = 1.0
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(relative * np.abs(theta) * scaled)


def _halves(rows: list[BalanceRows]) -> tuple[list[BalanceRows], list[BalanceRows]]:
    """The rows before and after the middle of their time span."""
    t = np.concatenate([r.t for r in rows])
    middle = 0.5 * (t.min() + t.max())
    first = [r.rows(r.t < middle) for r in rows]
    second = [r.rows(r.t >= middle) for r in rows]
    return [r for r in first if len(r) > 4], [r for r in second if len(r) > 4]


def _band_halves(builders: list[BalanceBuilder], choices: FitChoices
                 ) -> tuple[list[BalanceRows], list[BalanceRows]]:
    """Rows in the lower and upper halves of each torque band.

    The force rows, whose information starts at zero frequency, are compared at half
    their low-pass cut against the full cut instead: what the faster part of the motion
    adds must not move c_T or c_D beyond their σ (an unmodelled filter on the pose, such
    as an on-board estimator's, would).
    """
    low, high = [], []
    force = choices.force
    for band, out in ((0, low), (1, high)):
        rp = choices.roll_pitch.halves()[band] if choices.roll_pitch else None
        yw = choices.yaw.halves()[band] if choices.yaw else None
        fc = Band(0.0, 0.5 * force.high) if force is not None and band == 0 else None
        out.extend(balance_rows_for(builders, choices, rp, yw, fc))
    return low, high


def _sensor_prior(config: VehicleConfig, prior: ParameterEstimate) -> ParameterEstimate:
    """The prior of the sensors' quantities (a calibration the vehicle file states), σ 0
    elsewhere: θ's prior is a guess, and a model effect's a search range, not a measurement
    (`mavsysid.estimation.balance.theta.with_nuisance_prior`)."""
    sensor = np.array([q.term is not None and q.term.channel != "wrench"
                       for q in config.quantities])
    sigma = np.where(sensor, prior.sigma, 0.0)
    return ParameterEstimate(prior.value, np.diag(sigma**2), prior.names)


def _segments(flight: FlightData, settings: WrenchBalanceSettings) -> list[Segment]:
    segments = balance_segments(flight, settings.min_segment)
    if not segments:
        raise JobFailedError(f"{flight.source}: no stretch of at least "
                             f"{settings.min_segment:g} s without a gap in which the pose "
                             "changes: too short for the force and torque balance")
    return segments


def _answer(flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
            settings: WrenchBalanceSettings) -> tuple[WrenchBalanceResult, BalanceFit]:
    """The fit, θ, its widened σ and the statuses (no held-out check)."""
    segments = _segments(flight, settings)
    fit, builders = fit_balance(segments, config, float(prior.value[C_D]))
    sensors = _sensor_prior(config, prior)
    base = _fit_theta(fit, sensors)
    eiv, eiv_c = _eiv_sigma(fit, base, sensors)
    rows = fit.rows
    halves, halves_c = _split_sigma(*_halves(rows), sensors)
    bands, bands_c = _split_sigma(*_band_halves(builders, fit.choices), sensors)
    parts = np.vstack([base.sigma, eiv, halves, bands, base.route_sigma,
                       _thrust_row_sigma(fit, rows, base.value)])
    sigma = widened_sigma(parts)
    combo_sigma = widened_sigma([base.combination_sigma, eiv_c, halves_c, bands_c])
    determined = quantity_status(base.value, sigma, prior.sigma, settings.max_relative_sigma)
    value = np.where(determined, base.value, prior.value)
    cov = np.diag(np.where(determined, sigma, prior.sigma) ** 2)
    keep = np.flatnonzero(determined)
    corr = base.covariance[np.ix_(keep, keep)]
    scale = np.sqrt(np.abs(np.diag(corr)))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = np.nan_to_num(corr / np.outer(scale, scale))
    corr[np.diag_indices_from(corr)] = 1.0
    cov[np.ix_(keep, keep)] = corr * np.outer(sigma[keep], sigma[keep])
    result = WrenchBalanceResult(
        ParameterEstimate(value, cov, prior.names), determined, base, parts, combo_sigma, prior,
        fit.choices, delay_sigma(fit, builders), None, fit.force.rows,
        (_sources_note(segments[0]),))
    return result, fit


def _sources_note(segment: Segment) -> str:
    """Which measurement the balance compared with the model, in words."""
    if not isinstance(segment, ImuSegment):
        return ("the balance read the pose alone: its second derivatives for the specific "
                "force and the angular acceleration")
    force = ("the pose's second derivative (motion capture)" if segment.pose_position is not None
             else "the accelerometer")
    return (f"the balance read the gyro's derivative for the angular acceleration and {force} "
            "for the specific force")


def fit_wrench_balance(flight: FlightData, config: VehicleConfig,
                       prior: ParameterEstimate | None = None,
                       settings: WrenchBalanceSettings | None = None) -> WrenchBalanceResult:
    """θ per parameter from the flight's force and torque balance (module docstring).

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds (any segments; stretches shorter than ``min_segment`` are
        left out).
    config : VehicleConfig
        Mass and rotor geometry (known), and the prior θ.
    prior : ParameterEstimate, optional
        Default: the config's θ with the tool's default relative σ (50 %).
    settings : WrenchBalanceSettings, optional

    Returns
    -------
    WrenchBalanceResult
        Possibly determining no parameter (``determined`` all False; no held-out check
        then): its data θ is still the equation-error reference of the filter.

    Raises
    ------
    JobFailedError
        No usable stretch, or rotor speeds that contradict the vehicle's balance
        (`mavsysid.estimation.checks.check_rotor_balance`); one line.
    """
    settings = settings or WrenchBalanceSettings()
    prior = prior or prior_from_config(config)
    check_rotor_balance(flight, config)
    result, _ = _answer(flight, config, prior, settings)
    holdout = _holdout(flight, config, prior, settings) if result.determined.any() else None
    return WrenchBalanceResult(result.estimate, result.determined, result.data,
                               result.sigma_parts, result.combination_sigma, prior,
                               result.choices, result.delay_sigma, holdout, result.rows,
                               result.notes)


def balance_coefficients(flight: FlightData, config: VehicleConfig,
                         prior: ParameterEstimate | None = None) -> np.ndarray:
    """The stacked coefficients the balance fits on a flight, before θ is formed from them.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
    prior : ParameterEstimate, optional
        Default: the config's θ with the tool's default relative σ.

    Returns
    -------
    ndarray, shape (len(STACKED_COEFFICIENTS) + 2E,)
        `mavsysid.estimation.balance.rows.STACKED_COEFFICIENTS`, then the nuisance
        quantities' force and torque coefficients.
    """
    prior = prior or prior_from_config(config)
    _, fit = _answer(flight, config, prior, WrenchBalanceSettings())
    return stack(fit.force.coefficients, fit.torque.coefficients)


def _holdout(flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
             settings: WrenchBalanceSettings) -> HoldoutCheck | None:
    """Fit the start of the flight, predict its end (`mavsysid.estimation.balance.fit`)."""
    if not 0.0 < settings.holdout_fraction < 1.0:
        return None
    t0, t1 = float(flight.t[0]), float(flight.t[-1])
    cut = t1 - settings.holdout_fraction * (t1 - t0)
    try:
        train = balance_segments(flight.time_slice(t0, cut), settings.min_segment)
        fit, _ = fit_balance(train, config, float(prior.value[1])) if train else (None, None)
    except np.linalg.LinAlgError:
        return None
    if fit is None:
        return None
    test = balance_segments(flight.time_slice(cut, t1), 4 * fit.choices.window)
    if not test:
        return None
    model = stack(fit.force.coefficients, fit.torque.coefficients)
    return predict_holdout(test, config, fit.choices, model,
                           coefficients_from_theta(prior.value))


#: Savitzky–Golay window of the comparison without a balance, s: motion-capture noise
#: differentiated twice stays well below the rotor forces, manoeuvres of a few Hz pass.
SMOOTHING_WINDOW = 0.3


@dataclass(frozen=True)
class WrenchComparison:
    """Measured and model body wrench over the flight (M samples on uniform grids).

    Attributes
    ----------
    t : ndarray, shape (M,)
        s, the log's clock (smoother edges dropped; a NaN row between segments).
    measured_force, model_force : ndarray, shape (M, 3)
        Body force, N.
    measured_torque, model_torque : ndarray, shape (M, 3)
        Body torque, N·m, less the ω × J ω the model also predicts (J ω̇ on both sides).
    """

    t: np.ndarray
    measured_force: np.ndarray
    model_force: np.ndarray
    measured_torque: np.ndarray
    model_torque: np.ndarray


def compare_wrench(flight: FlightData, config: VehicleConfig, theta: np.ndarray,
                   window: float = SMOOTHING_WINDOW, delay: float = 0.0) -> WrenchComparison:
    """Measured and model body force and torque along a flight (module docstring).

    Both sides are the force and torque balance's rows (`mavsysid.estimation.balance.rows`:
    the pose smoothed and differentiated, the model through the same smoother) at the
    paper's model with θ, without band-pass, in the body frame and in N and N·m.

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds (any sampling; put on uniform grids here).
    config : VehicleConfig
        Mass and rotor geometry.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI (usually the final estimate).
    window : float
        Savitzky–Golay window, s (the balance's, when it ran).
    delay : float
        s by which the pose lags the rotor speeds (the balance's offset).

    Returns
    -------
    WrenchComparison
        Empty arrays when the flight is too short for the smoother.
    """
    theta = np.asarray(theta, float)
    b = coefficients_from_theta(theta)
    split = len(FORCE_COEFFICIENTS)
    parts = []
    for segment in uniform_segments(flight, 4.0 * window):
        rows = BalanceBuilder(segment, config, window).rows(delay, float(theta[1]),
                                                             magnitude=False)
        if len(rows):
            j = theta[3:6]
            parts.append(np.hstack([
                rows.t[:, None], config.mass * rows.force,
                config.mass * rows.force_columns @ b[:split], j * rows.torque,
                j * (rows.torque_columns @ b[split:])]))
            parts.append(np.full((1, 13), np.nan))
    if not parts:
        empty = np.empty((0, 3))
        return WrenchComparison(np.empty(0), empty, empty, empty, empty)
    x = np.vstack(parts[:-1])
    return WrenchComparison(x[:, 0], x[:, 1:4], x[:, 4:7], x[:, 7:10], x[:, 10:13])
