"""What estimation returns: parameter estimates with uncertainty, and their history."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vehicle.config import PARAMETER_NAMES

__all__ = ["EstimationHistory", "EstimationResult", "ParameterEstimate"]


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

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{"c_T": {"value": .., "sigma": ..}, ...}`` (DESIGN.md's estimate JSON)."""
        return {name: {"value": float(v), "sigma": float(s)}
                for name, v, s in zip(PARAMETER_NAMES, self.value, self.sigma, strict=True)}


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

    @property
    def final(self) -> ParameterEstimate:
        """The best estimate: refined if available, else filtered."""
        return self.refined if self.refined is not None else self.filtered
