"""What estimation returns: parameter estimates with uncertainty, and their history."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsysid.vehicle.config import PARAMETER_NAMES
from mavsysid.vehicle.model_effects import ModelEffect

__all__ = ["EstimationHistory", "EstimationResult", "FittedEffect", "ParameterEstimate"]

#: Two-sided 95 % quantile of the standard normal.
Z95 = 1.959963984540054


@dataclass(frozen=True)
class ParameterEstimate:
    """θ with its uncertainty, in SI units (order of `PARAMETER_NAMES`).

    Attributes
    ----------
    value : ndarray, shape (6,)
    covariance : ndarray, shape (6, 6)
    """

    value: np.ndarray
    covariance: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """Standard deviations, shape (6,)."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def relative_sigma(self) -> np.ndarray:
        """σ / |value|, shape (6,)."""
        return self.sigma / np.abs(self.value)

    @property
    def d_optimality(self) -> float:
        """det(Σ)^(1/6) via log-eigenvalues (paper Eq. dopt, docs/architecture.md), SI."""
        return float(np.exp(np.mean(np.log(np.linalg.eigvalsh(self.covariance)))))

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{"c_T": {"value": .., "sigma": ..}, ...}`` (docs/architecture.md's estimate JSON)."""
        return {name: {"value": float(v), "sigma": float(s)}
                for name, v, s in zip(PARAMETER_NAMES, self.value, self.sigma, strict=True)}


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
    """

    t: np.ndarray
    theta: np.ndarray
    theta_sigma: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    innovation: np.ndarray
    nis: np.ndarray


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
        θ by equation error (`mavsysid.estimation.equation_error_fit`), the independent
        check of the final θ; None when the guard is off.
    mismatch_widening : ndarray, shape (6,), or None
        σ multipliers (≥ 1) already applied to the final θ's covariance where it and the
        equation-error θ disagree beyond their σ
        (`mavsysid.estimation.robust_covariance.disagreement_widening`); None if not checked.
    answer : ParameterEstimate or None
        The per-parameter answer (`mavsysid.estimation.parameter_answer`): the filter's or
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
        The force and torque balance (`mavsysid.estimation.wrench_balance`), with its
        held-out check.
    filter_refusal : str or None
        Why the filter and batch could not answer (then ``filtered`` is the balance's θ and
        ``history`` is empty).
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

    @property
    def final(self) -> ParameterEstimate:
        """The best estimate: the per-parameter answer if formed, else refined, else filtered."""
        if self.answer is not None:
            return self.answer
        return self.refined if self.refined is not None else self.filtered
