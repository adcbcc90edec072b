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

from mavsysid.errors import JobFailedError

__all__ = ["NOISE_SCALE_BOUNDS", "NOISE_SCALE_LIMITS", "NoiseFit", "fit_noise_scale",
           "scaled_noise"]

#: Range of the noise scale searched first.
NOISE_SCALE_BOUNDS = (1e-3, 30.0)

#: How far the search extends beyond `NOISE_SCALE_BOUNDS` when the maximum lies at one of
#: its edges (real flights of small vehicles have needed ≈ 30×); a maximum at the edge of
#: these limits is reported as ``at_bound``.
NOISE_SCALE_LIMITS = (1e-4, 1e3)

_OVERFLOW_COST = 1e300


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
        The maximum lies at the edge of the search range (extended to ``limits``).
    at_upper_bound : bool
        ... at its upper edge: more unmodelled force than the range allows.
    """

    scale: float
    config: VehicleConfig
    run: FilterRun
    at_bound: bool
    at_upper_bound: bool = False


def scaled_noise(config: VehicleConfig, scale: float) -> VehicleConfig:
    """The config with its force and moment noise densities multiplied by ``scale``."""
    nz = config.noise
    return replace(config, noise=replace(nz, force_density=nz.force_density * scale,
                                         moment_density=nz.moment_density * scale))


def fit_noise_scale(
    flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
    sigma: tuple[float, float], state_sigma: tuple[float, float, float, float],
    bounds: tuple[float, float] = NOISE_SCALE_BOUNDS, wrench: np.ndarray | None = None,
    limits: tuple[float, float] = NOISE_SCALE_LIMITS,
) -> NoiseFit:
    """Maximise the innovation likelihood over one common noise scale (log-space search).

    Parameters
    ----------
    flight, config, prior, sigma, state_sigma, wrench
        As for `ParameterEKF` and `ParameterEKF.run` (``flight`` and ``wrench`` in the
        model's terms when there are known effects, `mavsysid.estimation.effect_channels`).
    bounds : tuple of 2 float
        Range of the scale searched first.
    limits : tuple of 2 float
        A maximum at the upper edge of ``bounds`` is searched for again between that edge
        and the upper limit (the first search's path, and so its result, stays as it was
        for maxima inside ``bounds``); the lower limit is not searched.
    """

    runs: dict[float, FilterRun] = {}

    def run_at(log_scale: float) -> FilterRun:
        # Each filter pass is the cost of the fit (≈ 1 s per 30 000 samples): keep them, so
        # the pass at the optimum is not run twice.
        if log_scale not in runs:
            cfg = scaled_noise(config, 10.0**log_scale)
            runs[log_scale] = ParameterEKF(cfg, prior, sigma).run(flight, state_sigma, wrench)
        return runs[log_scale]

    def cost(log_scale: float) -> float:
        try:
            return -run_at(log_scale).log_likelihood
        except JobFailedError:
            # A trial level at which the filter overflows is no maximum; a large finite
            # cost keeps the bounded Brent search's interpolation defined.
            return _OVERFLOW_COST

    def search(lo: float, hi: float) -> float:
        best = minimize_scalar(cost, bounds=(lo, hi),
                               method="bounded", options={"xatol": 0.02})
        return float(best.x)

    lo, hi = np.log10(bounds[0]), np.log10(bounds[1])
    x = search(lo, hi)
    far_hi = max(hi, np.log10(limits[1]))
    if hi - x < 0.05 and far_hi > hi:
        x = search(hi - 0.1, far_hi)
    # A maximum at the lower edge is not searched further: the model fits better than the
    # configured densities assume (a noise-free simulation does), and ten more filter passes
    # to find how much better would double the time of `estimate` on a long log.
    at_bound = bool(min(x - lo, far_hi - x) < 0.05)
    scale = 10.0 ** x
    return NoiseFit(scale, scaled_noise(config, scale), run_at(x), at_bound,
                    bool(far_hi - x < 0.05))
