"""Held-out validation: fit on the start of a flight, predict the forces and torques of the end.

The metric a researcher can check without knowing the truth (and the one data-driven
multirotor models are compared by, e.g. NeuroBEM's force and torque RMSE): the balance is
fitted on the first part of the flight (band, window, offset and θ all chosen there), and
the rest is predicted from its pose and rotor speeds. The RMSE of the measured minus the
predicted body specific force (m/s², the three axes pooled) and angular acceleration
(rad/s², in the band the fit used, the axes with a band pooled) is compared with the same
RMSE of the prior θ: a ratio below 1 is a model that predicts unseen data better than
the prior. Per-axis values are kept too.

The prediction uses the equation-error model as fitted to the training part (every
coefficient, the nuisance terms beyond the paper's model included); the prior's
prediction is the paper's model at the prior θ. It validates the fit, not the prior
values kept for parameters the flight does not determine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.balance_fit import FitChoices, balance_rows_for
from mavsysid.estimation.equation_error import AXIS_NAMES
from mavsysid.estimation.uniform_pose import UniformSegment
from mavsysid.estimation.wrench_regressors import FORCE_COEFFICIENTS, BalanceBuilder
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["HoldoutCheck", "predict_holdout"]


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
        """RMSE pooled over ``axes`` (one unit), fitted model / prior; NaN if none live."""
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


def predict_holdout(segments: list[UniformSegment], config: VehicleConfig,
                    choices: FitChoices, coefficients: np.ndarray,
                    prior_coefficients: np.ndarray) -> HoldoutCheck | None:
    """Predict the held-out segments with the training part's choices and coefficients.

    Parameters
    ----------
    segments : list of UniformSegment
        The held-out part.
    config : VehicleConfig
    choices : FitChoices
        The training part's window, bands and offset.
    coefficients, prior_coefficients : ndarray, shape (P,)
        Stacked force and torque coefficients (`STACKED_COEFFICIENTS`) of the fitted model
        and of the prior.

    Returns
    -------
    HoldoutCheck or None
        None when no held-out rows remain after the smoother's edges.
    """
    builders = [BalanceBuilder(s, config, choices.window) for s in segments
                if len(s) > 4 * choices.window / s.dt]
    rows = balance_rows_for(builders, choices) if builders else []
    if not rows:
        return None
    measured = np.concatenate([np.hstack([r.force, r.torque]) for r in rows])

    split = len(FORCE_COEFFICIENTS)

    def prediction(b: np.ndarray) -> np.ndarray:
        return np.concatenate([np.hstack([r.force_columns @ b[:split],
                                          r.torque_columns @ b[split:]]) for r in rows])

    def rmse(b: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean((measured - prediction(b)) ** 2, axis=0))

    live = np.any(measured != 0.0, axis=0)
    nan = np.where(live, 1.0, np.nan)
    return HoldoutCheck(float(segments[0].t[0]), rmse(coefficients) * nan,
                        rmse(prior_coefficients) * nan, len(measured))
