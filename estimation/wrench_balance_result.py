"""What `mavsysid.estimation.wrench_balance.fit_wrench_balance` returns, and its JSON."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.balance_fit import FitChoices
from mavsysid.estimation.holdout import HoldoutCheck
from mavsysid.estimation.parameter_status import (
    COMBINATION_NAMES,
    MAX_RELATIVE_SIGMA,
    SIGMA_PARTS,
    DataTheta,
    parameter_status,
)
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS

__all__ = ["WrenchBalanceResult"]


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass(frozen=True)
class WrenchBalanceResult:
    """What the flight's force and torque balance says about θ.

    Attributes
    ----------
    estimate : ParameterEstimate
        θ: the data's value and widened σ where determined, the prior's elsewhere (SI).
    determined : ndarray of bool, shape (6,)
    data : DataTheta
        The data-only values (also where not determined) and the combinations.
    sigma_parts : ndarray, shape (6, 6)
        σ of θ by source (`SIGMA_PARTS`), SI.
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

    @property
    def combination_determined(self) -> np.ndarray:
        """Which combinations (`COMBINATION_NAMES`) the flight determines, by the same rule."""
        return parameter_status(np.abs(self.data.combinations), self.combination_sigma,
                                MAX_RELATIVE_SIGMA)

    def as_dict(self) -> dict:
        """JSON-ready (SI; absent or infinite quantities are None).

        ``{"parameters": {name: {"value", "sigma", "unit", "status", "data_value",
        "data_sigma", "sigma_parts": {part: σ}, "prior_value", "prior_sigma"}},
        "combinations": {name: {"value", "sigma", "status"}}, "choices": {"window_s",
        "roll_pitch_band_hz", "yaw_band_hz", "force_lowpass_hz", "delay_s",
        "delay_sigma_s"}, "holdout": {…} or None, "rows", "notes"}``.
        """
        with np.errstate(over="ignore", invalid="ignore"):
            data_sigma = np.sqrt(np.sum(self.sigma_parts**2, axis=0))
        parameters = {}
        for k, name in enumerate(PARAMETER_NAMES):
            parameters[name] = {
                "value": _num(self.estimate.value[k]), "sigma": _num(self.estimate.sigma[k]),
                "unit": PARAMETER_UNITS[name], "status": self.status[k],
                "data_value": _num(self.data.value[k]), "data_sigma": _num(data_sigma[k]),
                "sigma_parts": {p: _num(v) for p, v in zip(SIGMA_PARTS, self.sigma_parts[:, k],
                                                          strict=True)},
                "prior_value": _num(self.prior.value[k]), "prior_sigma": _num(self.prior.sigma[k])}
        combinations = {
            name: {"value": _num(v), "sigma": _num(s),
                   "status": "determined" if d else "not determined"}
            for name, v, s, d in zip(COMBINATION_NAMES, self.data.combinations,
                                     self.combination_sigma, self.combination_determined,
                                     strict=True)}
        c = self.choices

        def band(b):
            return None if b is None else [float(b.low), float(b.high)]

        return {"parameters": parameters, "combinations": combinations,
                "choices": {"window_s": c.window, "roll_pitch_band_hz": band(c.roll_pitch),
                            "yaw_band_hz": band(c.yaw),
                            "force_lowpass_hz": None if c.force is None else float(c.force.high),
                            "delay_s": c.delay, "delay_sigma_s": _num(self.delay_sigma)},
                "holdout": None if self.holdout is None else self.holdout.as_dict(),
                "rows": self.rows, "notes": list(self.notes)}
