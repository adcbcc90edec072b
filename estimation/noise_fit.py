"""Fitting the process-noise level to the flight: maximum likelihood on the innovations.

The force and moment noise densities of the vehicle config are assumptions. How much
unmodelled force and moment a flight really shows can be read off the data: the filter's
innovation log-likelihood Σ log N(y_k; 0, S_k) is a function of the noise scale, and its
maximum is the maximum-likelihood noise level (the classical way to tune a Kalman filter
from data). Too much assumed noise throws information away; too little makes the filter
and its σ overconfident (what the paper saw on real flights). Batch refinement runs at
the fitted level.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from mavsysid.estimation.ekf import FilterRun, ParameterEKF
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.config import VehicleConfig
from scipy.optimize import minimize_scalar

__all__ = ["NOISE_SCALE_BOUNDS", "NoiseFit", "fit_noise_scale", "scaled_noise"]

#: Range of the noise scale searched by default.
NOISE_SCALE_BOUNDS = (1e-3, 30.0)


@dataclass(frozen=True)
class NoiseFit:
    """The fitted noise scale and the filter run at that scale.

    Attributes
    ----------
    scale : float
        Factor applied to both the force and the moment noise densities of the config.
    config : VehicleConfig
        The config with the scaled densities.
    run : FilterRun
        The filter over the flight at the fitted scale.
    at_bound : bool
        The maximum lies at the edge of the search range.
    """

    scale: float
    config: VehicleConfig
    run: FilterRun
    at_bound: bool


def scaled_noise(config: VehicleConfig, scale: float) -> VehicleConfig:
    """The config with its force and moment noise densities multiplied by ``scale``."""
    nz = config.noise
    return replace(config, noise=replace(nz, force_density=nz.force_density * scale,
                                         moment_density=nz.moment_density * scale))


def fit_noise_scale(
    flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
    sigma: tuple[float, float], state_sigma: tuple[float, float, float, float],
    bounds: tuple[float, float] = NOISE_SCALE_BOUNDS, wrench: np.ndarray | None = None,
) -> NoiseFit:
    """Maximise the innovation likelihood over one common noise scale (log-space search).

    Parameters
    ----------
    flight, config, prior, sigma, state_sigma, wrench
        As for `ParameterEKF` and `ParameterEKF.run` (``flight`` and ``wrench`` in the
        model's terms when there are known effects, `mavsysid.estimation.effect_channels`).
    bounds : tuple of 2 float
        Range of the scale searched.
    """

    def run_at(log_scale: float) -> FilterRun:
        cfg = scaled_noise(config, 10.0**log_scale)
        return ParameterEKF(cfg, prior, sigma).run(flight, state_sigma, wrench)

    lo, hi = np.log10(bounds[0]), np.log10(bounds[1])
    best = minimize_scalar(lambda s: -run_at(s).log_likelihood, bounds=(lo, hi),
                           method="bounded", options={"xatol": 0.02})
    scale = 10.0 ** float(best.x)
    at_bound = bool(min(best.x - lo, hi - best.x) < 0.05)
    return NoiseFit(scale, scaled_noise(config, scale), run_at(float(best.x)), at_bound)
