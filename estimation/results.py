"""What estimation returns, and the words of its answer.

`ParameterEstimate` (values and covariance of the estimated quantities by name),
`EstimationResult` (everything ``estimate`` reports: the prior, the filter and the batch,
the history, the balance and the per-quantity answer), `EstimationHistory`,
`FittedEffect`; the balance's `WrenchBalanceResult` with its `DataTheta`, `FitChoices` and
`HoldoutCheck`. The answer's words: `DETERMINED`, `NOT_DETERMINED`, `AT_BOUND`, and the
rule that says which (`parameter_status`, `quantity_status`): a parameter of θ is
determined by the flight when its value is physical (positive) and its σ is at most
`MAX_RELATIVE_SIGMA` of it, its 95 % interval about ±25 %: a fourfold narrowing of the
tool's default prior (σ = `PRIOR_RELATIVE_SIGMA` of the nominal); a nuisance quantity
when its σ is as much narrower than its prior's. The prior itself: `prior_from_config`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import astuple, dataclass, replace
from functools import lru_cache
from typing import Any, Protocol

import numpy as np
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, VehicleConfig
from mavsysid.vehicle.model_effects import ModelEffect
from mavsysid.vehicle.parameters import C_D, MAX_RELATIVE_SIGMA, quantity_names

from mavsysid.errors import InputError

__all__ = [
    "AT_BOUND",
    "AXIS_NAMES",
    "AXIS_UNITS",
    "COMBINATION_NAMES",
    "CONVERGENCE_TOLERANCE",
    "C_D_PRIOR_SIGMA",
    "DETERMINED",
    "FILTER_ORDER",
    "MAX_RELATIVE_SIGMA",
    "NOT_DETERMINED",
    "PRIOR_RELATIVE_SIGMA",
    "SIGMA_PARTS",
    "Band",
    "DataTheta",
    "EstimationHistory",
    "EstimationResult",
    "FitChoices",
    "FittedEffect",
    "HoldoutCheck",
    "NoiseMet",
    "ParameterEstimate",
    "PriorChoices",
    "WrenchBalanceResult",
    "convergence_time",
    "parameter_status",
    "prior_from_config",
    "quantity_status",
]

#: Two-sided 95 % quantile of the standard normal.
Z95 = 1.959963984540054

#: σ of the prior on each parameter relative to the vehicle file's value (the tool's default).
PRIOR_RELATIVE_SIGMA = 0.5
#: σ of c_D's prior where the vehicle file's c_D is 0, s/m.
C_D_PRIOR_SIGMA = 0.01


class PriorChoices(Protocol):
    """How wide the prior is (`mavsysid.estimation.filter.estimator.EstimatorSettings`)."""

    prior_relative_sigma: float
    c_D_scale: float


@dataclass(frozen=True)
class ParameterEstimate:
    """The estimated quantities with their uncertainty, in SI units.

    θ of the paper first (the order of `PARAMETER_NAMES`), then any nuisance quantities
    (`mavsysid.vehicle.parameters.EstimatedQuantity`), as ``names`` says.

    Attributes
    ----------
    value : ndarray, shape (P,)
    covariance : ndarray, shape (P, P)
    names : tuple of str
        The quantities' names; `PARAMETER_NAMES` when not given (then P must be 6).
    """

    value: np.ndarray
    covariance: np.ndarray
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.names:
            if np.size(self.value) != len(PARAMETER_NAMES):
                raise ValueError(f"{np.size(self.value)} quantities need their names")
            object.__setattr__(self, "names", PARAMETER_NAMES)

    @property
    def sigma(self) -> np.ndarray:
        """Standard deviations, shape (P,)."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def relative_sigma(self) -> np.ndarray:
        """σ / |value|, shape (P,)."""
        return self.sigma / np.abs(self.value)

    @property
    def theta(self) -> ParameterEstimate:
        """The paper's θ alone (the first six quantities)."""
        six = slice(0, len(PARAMETER_NAMES))
        return ParameterEstimate(self.value[six], self.covariance[six, six])

    def subset(self, names: tuple[str, ...]) -> ParameterEstimate:
        """The named quantities alone, in the order of ``names``.

        Parameters
        ----------
        names : tuple of str
            Each one of ``self.names``.
        """
        idx = [self.names.index(name) for name in names]
        return ParameterEstimate(self.value[idx], self.covariance[np.ix_(idx, idx)],
                                 tuple(names))

    def on(self, prior: ParameterEstimate) -> ParameterEstimate:
        """This estimate on the quantities of ``prior``: a quantity it lacks keeps the prior's
        value and σ, uncorrelated with the rest.

        Parameters
        ----------
        prior : ParameterEstimate
            The quantities to answer and their values where this estimate lacks one.
        """
        value = prior.value.astype(float).copy()
        cov = np.diag(prior.sigma**2)
        mine = [j for j, name in enumerate(prior.names) if name in self.names]
        idx = [self.names.index(prior.names[j]) for j in mine]
        value[mine] = self.value[idx]
        cov[np.ix_(mine, mine)] = self.covariance[np.ix_(idx, idx)]
        return ParameterEstimate(value, cov, prior.names)

    @property
    def d_optimality(self) -> float:
        """det(Σ_θ)^(1/6) of the paper's θ via log-eigenvalues (paper Eq. dopt,
        docs/architecture.md), SI; nuisance quantities are marginalised out.

        Σ_θ's variances span twenty decades on a small vehicle (c_M² against a c_D left at
        its prior), below the eigensolver's absolute precision: the determinant is taken
        as ∏σ_j² · det(R) of the correlation matrix R, whose eigenvalues are O(1). NaN
        where Σ_θ is not positive definite.
        """
        cov = self.theta.covariance
        sigma = np.sqrt(np.diag(cov))
        if not np.all(sigma > 0.0):  # a variance 0 (det 0) or not a number
            with np.errstate(invalid="ignore", divide="ignore"):
                return float(np.exp(np.mean(np.log(np.linalg.eigvalsh(cov)))))
        with np.errstate(invalid="ignore", divide="ignore"):
            correlation = cov / np.outer(sigma, sigma)
            log_det = 2.0 * np.sum(np.log(sigma)) + np.sum(np.log(
                np.linalg.eigvalsh(correlation)))
        return float(np.exp(log_det / len(sigma)))

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{"c_T": {"value": .., "sigma": ..}, ...}`` (docs/architecture.md's estimate JSON)."""
        return {name: {"value": float(v), "sigma": float(s)}
                for name, v, s in zip(self.names, self.value, self.sigma, strict=True)}


@dataclass(frozen=True)
class FittedEffect:
    """A model effect as the estimator used it: its parameter values and their σ.

    Attributes
    ----------
    effect : ModelEffect
        The effect with the values used (the fitted ones when ``fitted``).
    sigma : ndarray, shape (P,)
        σ of each parameter, SI (the effect's parameter order); NaN when not fitted
        (values taken as known).
    fitted : bool
        Whether the values were estimated from this flight (jointly with θ).
    """

    effect: ModelEffect
    sigma: np.ndarray
    fitted: bool

    @property
    def name(self) -> str:
        """The effect's stable identifier (``motor_lag`` …)."""
        return self.effect.name

    @property
    def value(self) -> np.ndarray:
        """Parameter values, SI, shape (P,)."""
        return self.effect.values

    @property
    def ci95(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper 95 % bounds (value ∓ 1.96 σ), SI, each shape (P,)."""
        return self.value - Z95 * self.sigma, self.value + Z95 * self.sigma

    def as_dict(self) -> dict:
        """``{"name", "fitted", "parameters": {p: {"value", "sigma", "ci95", "unit"}}}``.

        JSON-ready: σ and the interval are None when not fitted.
        """
        lo, hi = self.ci95

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        params = {
            p.name: {"value": float(v), "sigma": num(s), "ci95": None if not math.isfinite(s)
                     else [float(a), float(b)], "unit": p.unit}
            for p, v, s, a, b in zip(self.effect.parameters, self.value, self.sigma, lo, hi,
                                     strict=True)}
        return {"name": self.name, "fitted": self.fitted, "parameters": params}


@dataclass(frozen=True)
class EstimationHistory:
    """The filter over time, one row per measurement (N rows).

    Attributes
    ----------
    t : ndarray, shape (N,)
        s.
    theta : ndarray, shape (N, 6)
        Filtered θ after each update, SI.
    theta_sigma : ndarray, shape (N, 6)
        Its σ, SI.
    position : ndarray, shape (N, 3)
        Filtered position, m.
    quaternion : ndarray, shape (N, 4)
        Filtered attitude.
    innovation : ndarray, shape (N, 6)
        Measurement residuals before each update: position (m) and attitude (rad).
    nis : ndarray, shape (N,)
        Normalised innovation squared yᵀ S⁻¹ y (χ² with 6 degrees of freedom if consistent).
    imu_nis : ndarray, shape (N,), or None
        The IMU update's NIS at each sample (χ² with as many degrees of freedom as readings,
        6 for a gyro and an accelerometer; NaN where none); None: the filter read no IMU.
    """

    t: np.ndarray
    theta: np.ndarray
    theta_sigma: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    innovation: np.ndarray
    nis: np.ndarray
    imu_nis: np.ndarray | None = None


@dataclass(frozen=True)
class NoiseMet:
    """The noise the filter met on a flight: what a plan for the next flight of the vehicle
    must expect of the estimator (``plan --noise-from``).

    Attributes
    ----------
    position_sigma : float
        Pose position σ the filter used, m.
    attitude_sigma : float
        Pose attitude σ the filter used, rad.
    pose_rate : float
        Pose samples per second it read, Hz.
    force_density : float
        White-noise density of the unmodelled force at the level fitted to the flight
        (the configured one without refinement), N·√s.
    moment_density : float
        The same for the moment, N·m·√s.
    """

    position_sigma: float
    attitude_sigma: float
    pose_rate: float
    force_density: float
    moment_density: float

    @classmethod
    def median(cls, mets: Sequence[NoiseMet]) -> NoiseMet:
        """Each quantity's median over several flights' noise: the level a next flight meets
        (the fitted level varies from flight to flight, even on one trajectory).

        Parameters
        ----------
        mets : sequence of NoiseMet
            At least one.
        """
        if not mets:
            raise ValueError("no noise to take the median of")
        values = np.median([astuple(m) for m in mets], axis=0)
        return cls(*(float(v) for v in values))

    def applied_to(self, config: VehicleConfig) -> VehicleConfig:
        """``config`` whose noise is this: pose σ and process-noise densities.

        Parameters
        ----------
        config : VehicleConfig
            The vehicle; its θ, geometry and limits are kept.
        """
        noise = replace(config.noise, position_sigma=self.position_sigma,
                        attitude_sigma=self.attitude_sigma,
                        force_density=self.force_density, moment_density=self.moment_density)
        return replace(config, noise=noise)


@dataclass(frozen=True)
class EstimationResult:
    """Everything `estimate` reports.

    Attributes
    ----------
    prior : ParameterEstimate
        The prior (config's nominal θ with its relative σ).
    filtered : ParameterEstimate
        The EKF's final estimate.
    refined : ParameterEstimate or None
        The batch MAP estimate, when refinement ran.
    history : EstimationHistory
        The filter over time.
    convergence_time : ndarray, shape (6,)
        Per parameter: the first time after which the filtered estimate stays within 5 % of
        the truth (when known) or of the final estimate; NaN when it never does. s from the
        start of the log.
    true_theta : ndarray or None
        True θ when the log carries it (simulated flights).
    measurement_sigma : tuple of 2 float
        Position σ (m) and attitude σ (rad) the filter assumed.
    pose_source : str
        "motion_capture" or "autopilot".
    notes : tuple of str
        Lines to show the user (warnings from reading, assumptions made).
    effects : tuple of FittedEffect
        The model effects the estimate includes (config's or caller's), in their order;
        empty for the paper's model.
    log_likelihood : float
        Innovation log-likelihood Σ log N(y_k; 0, S_k) of the filter at the fitted process
        noise and effects (at the config's noise when refinement is off); NaN if unknown.
    equation_error : ParameterEstimate or None
        θ by equation error (the force and torque balance's with the prior,
        `WrenchBalanceResult.with_prior`), the independent check of the final θ; None when
        the guard is off.
    mismatch_widening : ndarray, shape (6,), or None
        σ multipliers (≥ 1) already applied to the final θ's covariance where it and the
        equation-error θ disagree beyond their σ
        (`mavsysid.estimation.robust.disagreement_widening`); None if not checked.
    answer : ParameterEstimate or None
        The per-parameter answer (`mavsysid.estimation.answer`): the filter's or
        the force and torque balance's value per parameter, the prior's where the flight
        determines nothing; `final` when set.
    status : tuple of str
        Per parameter, with ``answer``: "determined", "not determined by this flight" or
        "at the bound"; empty without it.
    answer_source : tuple of str
        Per parameter, with ``answer``: "filter", "balance" or "prior".
    mismatch : tuple of str
        Parameters where the filter and the balance disagree (the balance answers).
    balance : WrenchBalanceResult or None
        The force and torque balance (`mavsysid.estimation.balance.fit`), with its
        held-out check.
    filter_refusal : str or None
        Why the filter and batch could not answer (then ``filtered`` is the balance's θ and
        ``history`` is empty).
    process_noise : tuple of 2 float or None
        The force (N·√s) and moment (N·m·√s) white-noise densities the filter ran at (the
        level fitted to the flight, or the configured one without refinement); None where
        no filter ran.
    pose_rate : float
        Pose samples per second the filter read, Hz (NaN where unknown).
    """

    prior: ParameterEstimate
    filtered: ParameterEstimate
    refined: ParameterEstimate | None
    history: EstimationHistory
    convergence_time: np.ndarray
    true_theta: np.ndarray | None
    measurement_sigma: tuple[float, float]
    pose_source: str
    notes: tuple[str, ...] = ()
    effects: tuple[FittedEffect, ...] = ()
    log_likelihood: float = math.nan
    equation_error: ParameterEstimate | None = None
    mismatch_widening: np.ndarray | None = None
    answer: ParameterEstimate | None = None
    status: tuple[str, ...] = ()
    answer_source: tuple[str, ...] = ()
    mismatch: tuple[str, ...] = ()
    balance: Any = None
    filter_refusal: str | None = None
    process_noise: tuple[float, float] | None = None
    pose_rate: float = math.nan

    @property
    def noise_met(self) -> NoiseMet | None:
        """The noise the filter met on this flight (pose σ and rate, the densities it ran
        at); None where no filter ran or its result was refused."""
        if self.process_noise is None or self.filter_refusal is not None:
            return None
        return NoiseMet(*self.measurement_sigma, self.pose_rate, *self.process_noise)

    @property
    def final(self) -> ParameterEstimate:
        """The best estimate: the per-parameter answer if formed, else refined, else filtered."""
        if self.answer is not None:
            return self.answer
        return self.refined if self.refined is not None else self.filtered


#: The parts of σ, in the order of `DataTheta.parts`.
SIGMA_PARTS = ("newey_west", "errors_in_variables", "flight_halves", "band_halves",
               "j_z_routes", "thrust_row")


#: Combinations a flight may determine when a parameter alone is not: the yaw ratio and
#: the rotors' inertia relative to the yaw inertia.
COMBINATION_NAMES = ("c_M/j_z", "J_r/j_z")


@dataclass(frozen=True)
class DataTheta:
    """θ (and the combinations) as the flight's data alone give them.

    Attributes
    ----------
    value : ndarray, shape (6,)
        SI; NaN where not formed.
    covariance : ndarray, shape (6, 6)
        Delta-method covariance of the Newey–West sandwich.
    combinations : ndarray, shape (2,)
        `COMBINATION_NAMES` values.
    combination_sigma : ndarray, shape (2,)
    route_sigma : ndarray, shape (6,)
        σ added by the disagreement of the two routes to j_z (on j_z and c_M).
    """

    value: np.ndarray
    covariance: np.ndarray
    combinations: np.ndarray
    combination_sigma: np.ndarray
    route_sigma: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """Sandwich σ of θ, shape (6,)."""
        return np.sqrt(np.abs(np.diag(self.covariance)))


def parameter_status(value: np.ndarray, sigma: np.ndarray,
                     max_relative_sigma: float = MAX_RELATIVE_SIGMA) -> np.ndarray:
    """Which parameters the flight determines (module docstring), shape like ``value``.

    Parameters
    ----------
    value, sigma : ndarray
        Data-only values and widened σ (c_D may be 0 only if its σ is too).
    max_relative_sigma : float
    """
    value, sigma = np.asarray(value, float), np.asarray(sigma, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = np.isfinite(value) & np.isfinite(sigma) & (value > 0.0)
        return ok & (sigma <= max_relative_sigma * np.abs(value))


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
class HoldoutCheck:
    """Held-out RMSE of the fitted model and of the prior (per axis of `AXIS_NAMES`).

    Attributes
    ----------
    start : float
        Time the held-out part starts, s.
    rmse : ndarray, shape (6,)
        Fitted model, SI (NaN for an axis without a band).
    prior_rmse : ndarray, shape (6,)
        Prior θ.
    rows : int
        Held-out rows compared.
    """

    start: float
    rmse: np.ndarray
    prior_rmse: np.ndarray
    rows: int

    @property
    def ratio(self) -> np.ndarray:
        """rmse / prior_rmse per axis, shape (6,)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.rmse / self.prior_rmse

    def group_ratio(self, axes: slice) -> float:
        """RMSE pooled over ``axes`` (one unit), fitted model / prior; NaN if none live.

        Parameters
        ----------
        axes : slice
            Axes of `AXIS_NAMES` in one unit (the forces, or the angular accelerations).
        """
        model, prior = self.rmse[axes], self.prior_rmse[axes]
        live = np.isfinite(model) & np.isfinite(prior)
        if not live.any() or not np.any(prior[live] > 0):
            return float("nan")
        return float(np.sqrt(np.sum(model[live] ** 2) / np.sum(prior[live] ** 2)))

    @property
    def force_ratio(self) -> float:
        """Force RMSE (the three axes pooled), fitted / prior."""
        return self.group_ratio(slice(0, 3))

    @property
    def torque_ratio(self) -> float:
        """Angular-acceleration RMSE (the axes with a band pooled), fitted / prior."""
        return self.group_ratio(slice(3, 6))

    @property
    def overall_ratio(self) -> float:
        """Geometric mean of the force and torque ratios (the one that exists if only one)."""
        live = [r for r in (self.force_ratio, self.torque_ratio) if np.isfinite(r)]
        return float(np.exp(np.mean(np.log(live)))) if live else float("nan")

    def as_dict(self) -> dict:
        """JSON-ready: per axis rmse, prior_rmse, ratio; the force, torque and overall ratios."""
        def num(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None

        return {"start_s": self.start, "rows": self.rows,
                "axes": {a: {"rmse": num(m), "prior_rmse": num(p), "ratio": num(r)}
                         for a, m, p, r in zip(AXIS_NAMES, self.rmse, self.prior_rmse,
                                               self.ratio, strict=True)},
                "force_ratio": num(self.force_ratio), "torque_ratio": num(self.torque_ratio),
                "ratio": num(self.overall_ratio)}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass(frozen=True)
class WrenchBalanceResult:
    """What the flight's force and torque balance says about θ.

    Attributes
    ----------
    estimate : ParameterEstimate
        θ: the data's value and widened σ where determined, the prior's elsewhere (SI).
    determined : ndarray of bool, shape (P,)
    data : DataTheta
        The data-only values (also where not determined) and the combinations.
    sigma_parts : ndarray, shape (len(SIGMA_PARTS), P)
        σ of each quantity by source (`SIGMA_PARTS`), SI.
    combination_sigma : ndarray, shape (2,)
        Widened σ of the combinations (`COMBINATION_NAMES`).
    prior : ParameterEstimate
    choices : FitChoices
        Window, bands and the offset δ (the pose lags the rotor speeds by δ).
    delay_sigma : float
        σ of δ, s.
    holdout : HoldoutCheck or None
    rows : int
        Rows of the force fit (after thinning).
    notes : tuple of str
    """

    estimate: ParameterEstimate
    determined: np.ndarray
    data: DataTheta
    sigma_parts: np.ndarray
    combination_sigma: np.ndarray
    prior: ParameterEstimate
    choices: FitChoices
    delay_sigma: float
    holdout: HoldoutCheck | None
    rows: int
    notes: tuple[str, ...] = ()

    @property
    def status(self) -> tuple[str, ...]:
        """Per parameter: "determined" or "not determined"."""
        return tuple("determined" if d else "not determined" for d in self.determined)

    def with_prior(self, prior: ParameterEstimate) -> ParameterEstimate:
        """The data's θ combined with ``prior`` by inverse variance, per parameter (SI).

        The equation-error θ as the filter takes it (restart point, agreement check): the
        data's value where it is precise, pulled to the prior where it is not; a parameter
        without a data value keeps the prior's. Diagonal covariance.

        Parameters
        ----------
        prior : ParameterEstimate
            The prior θ and covariance, SI.
        """
        value = np.asarray(self.data.value, float)
        with np.errstate(over="ignore", invalid="ignore"):
            sigma = np.sqrt(np.sum(self.sigma_parts**2, axis=0))
        has = np.isfinite(value) & np.isfinite(sigma) & (sigma > 0.0)
        w_data = np.where(has, 1.0 / np.where(has, sigma, 1.0) ** 2, 0.0)
        w_prior = 1.0 / prior.sigma**2
        mean = (w_data * np.where(has, value, 0.0) + w_prior * prior.value) / (w_data + w_prior)
        return ParameterEstimate(mean, np.diag(1.0 / (w_data + w_prior)), prior.names)

    @property
    def combination_determined(self) -> np.ndarray:
        """Which combinations (`COMBINATION_NAMES`) the flight determines, by the same rule."""
        return parameter_status(np.abs(self.data.combinations), self.combination_sigma,
                                MAX_RELATIVE_SIGMA)

    def as_dict(self) -> dict:
        """JSON-ready (SI; absent or infinite quantities are None).

        ``{"parameters": {name: {"value", "sigma", "unit", "status", "data_value",
        "data_sigma", "sigma_parts": {part: σ}, "prior_value", "prior_sigma"}},
        "nuisance": {name: {the same but "unit"}}, "combinations": {name: {"value",
        "sigma", "status"}}, "choices": {"window_s", "roll_pitch_band_hz", "yaw_band_hz",
        "force_lowpass_hz", "delay_s", "delay_sigma_s"}, "holdout": {…} or None, "rows",
        "notes"}``; "nuisance" only when the balance estimated quantities beyond θ.
        """
        with np.errstate(over="ignore", invalid="ignore"):
            data_sigma = np.sqrt(np.sum(self.sigma_parts**2, axis=0))
        quantities = {}
        for k, name in enumerate(self.estimate.names):
            quantities[name] = {
                "value": _num(self.estimate.value[k]), "sigma": _num(self.estimate.sigma[k]),
                "unit": PARAMETER_UNITS.get(name), "status": self.status[k],
                "data_value": _num(self.data.value[k]), "data_sigma": _num(data_sigma[k]),
                "sigma_parts": {p: _num(v) for p, v in zip(SIGMA_PARTS, self.sigma_parts[:, k],
                                                          strict=True)},
                "prior_value": _num(self.prior.value[k]), "prior_sigma": _num(self.prior.sigma[k])}
        parameters = {name: quantities.pop(name) for name in PARAMETER_NAMES}
        for entry in quantities.values():
            del entry["unit"]
        combinations = {
            name: {"value": _num(v), "sigma": _num(s),
                   "status": "determined" if d else "not determined"}
            for name, v, s, d in zip(COMBINATION_NAMES, self.data.combinations,
                                     self.combination_sigma, self.combination_determined,
                                     strict=True)}
        c = self.choices

        def band(b):
            return None if b is None else [float(b.low), float(b.high)]

        nuisance = {"nuisance": quantities} if quantities else {}
        return {"parameters": parameters, **nuisance, "combinations": combinations,
                "choices": {"window_s": c.window, "roll_pitch_band_hz": band(c.roll_pitch),
                            "yaw_band_hz": band(c.yaw),
                            "force_lowpass_hz": None if c.force is None else float(c.force.high),
                            "delay_s": c.delay, "delay_sigma_s": _num(self.delay_sigma)},
                "holdout": None if self.holdout is None else self.holdout.as_dict(),
                "rows": self.rows, "notes": list(self.notes)}


DETERMINED = "determined"


NOT_DETERMINED = "not determined by this flight"


AT_BOUND = "at the bound"


def quantity_status(value: np.ndarray, sigma: np.ndarray, prior_sigma: np.ndarray,
                    max_relative_sigma: float = MAX_RELATIVE_SIGMA) -> np.ndarray:
    """Which quantities an estimate determines, shape like ``value`` (P,).

    θ by `parameter_status` (physical and σ within ``max_relative_sigma`` of the value); a
    nuisance quantity, whose value may well be 0, when its σ is as much narrower than its
    prior's as θ's rule asks of the default prior (`PRIOR_RELATIVE_SIGMA`): fourfold.

    Parameters
    ----------
    value, sigma, prior_sigma : ndarray, shape (P,)
        The estimate, its σ and the prior's σ, SI.
    max_relative_sigma : float
    """
    value, sigma = np.asarray(value, float), np.asarray(sigma, float)
    out = np.zeros(value.shape, bool)
    six = len(PARAMETER_NAMES)
    out[:six] = parameter_status(value[:six], sigma[:six], max_relative_sigma)
    narrowing = max_relative_sigma / PRIOR_RELATIVE_SIGMA
    with np.errstate(invalid="ignore"):
        out[six:] = np.isfinite(value[six:]) & (
            sigma[six:] <= narrowing * np.asarray(prior_sigma, float)[six:])
    return out


def prior_from_config(config: VehicleConfig, settings: PriorChoices | None = None
                      ) -> ParameterEstimate:
    """The prior: the config's nominal θ with σ = relative σ × |θ| (c_D: a floor if 0), then
    each of the config's nuisance quantities at its own prior value and σ.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle file: its θ is the prior's value; its ``extra_quantities`` follow.
    settings : PriorChoices, optional
        The relative σ and c_D's σ where its value is 0 (default `PRIOR_RELATIVE_SIGMA`,
        `C_D_PRIOR_SIGMA`).

    Raises
    ------
    InputError
        A relative σ that is not positive, or a nuisance quantity without a positive σ.
    """
    relative = PRIOR_RELATIVE_SIGMA if settings is None else settings.prior_relative_sigma
    c_d_sigma = C_D_PRIOR_SIGMA if settings is None else settings.c_D_scale
    if not relative > 0.0:
        raise InputError(f"prior relative σ {relative:g}: expected > 0")
    value = config.theta.copy()
    sigma = relative * np.abs(value)
    if value[C_D] == 0.0:
        sigma[C_D] = c_d_sigma
    extras = config.extra_quantities
    for quantity in extras:
        if not quantity.prior_sigma > 0.0:
            raise InputError(f"estimated quantity {quantity.name}: prior σ "
                             f"{quantity.prior_sigma:g}: expected > 0")
    value = np.concatenate([value, [q.nominal for q in extras]])
    sigma = np.concatenate([sigma, [q.prior_sigma for q in extras]])
    return ParameterEstimate(value, np.diag(sigma**2), quantity_names(extras))


#: Relative band that counts as converged (the paper's "within 5 %").
CONVERGENCE_TOLERANCE = 0.05


def convergence_time(
    t: np.ndarray,
    theta: np.ndarray,
    reference: np.ndarray,
    tolerance: float = CONVERGENCE_TOLERANCE,
) -> np.ndarray:
    """When each parameter's estimate settles within a relative band around a reference.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, increasing.
    theta : ndarray, shape (N, P)
        Estimates over time (P = 6 for θ), SI.
    reference : ndarray, shape (P,)
        Values to converge to (the truth, or the final estimate), SI.
    tolerance : float, optional
        Half-width of the band relative to ``|reference|`` (0.05 = 5 %).

    Returns
    -------
    ndarray, shape (P,)
        Per parameter, the first t_i such that ``|theta[k, j] - reference[j]| <=
        tolerance * |reference[j]|`` for every k ≥ i, s; NaN when the last sample is
        outside the band (or there are no samples). A NaN estimate counts as outside.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    theta = np.asarray(theta, dtype=float)
    reference = np.asarray(reference, dtype=float).reshape(-1)
    if theta.ndim != 2 or theta.shape != (t.size, reference.size):
        raise ValueError(
            f"convergence_time: theta of shape ({t.size}, {reference.size}) to match t "
            f"and reference, got {theta.shape}"
        )
    out = np.full(reference.size, np.nan)
    if t.size == 0:
        return out
    inside = np.abs(theta - reference) <= tolerance * np.abs(reference)
    # A reversed running AND marks the samples from which the estimate never leaves again.
    stays = np.logical_and.accumulate(inside[::-1], axis=0)[::-1]
    settled = stays[-1]
    out[settled] = t[np.argmax(stays[:, settled], axis=0)]
    return out


#: The six residual axes: body specific force (m/s²) and angular acceleration (rad/s²).
AXIS_NAMES = ("f_x", "f_y", "f_z", "dw_x", "dw_y", "dw_z")


AXIS_UNITS = ("m/s²",) * 3 + ("rad/s²",) * 3


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
        from scipy.signal import sosfiltfilt  # slow to import: only where filtered

        sos = _sos(self.low, self.high, dt)
        shape = x.shape
        flat = np.asarray(x, float).reshape(shape[0], -1)
        return sosfiltfilt(sos, flat, axis=0).reshape(shape)

    def settle(self) -> float:
        """Time to cut off each end after filtering, s: one period of the lowest frequency."""
        return 1.0 / (self.low if self.low > 0 else self.high)


@lru_cache(maxsize=64)
def _sos(low: float, high: float, dt: float) -> np.ndarray:
    from scipy.signal import butter

    nyquist = 0.5 / dt
    high = min(high, 0.95 * nyquist)
    if low > 0:
        return butter(FILTER_ORDER, [low, high], btype="bandpass", fs=1.0 / dt, output="sos")
    return butter(FILTER_ORDER, high, btype="lowpass", fs=1.0 / dt, output="sos")
