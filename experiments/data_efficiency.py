"""The data-efficiency endpoint, in place of the paper's median-of-estimates convergence time.

Two figures per experiment:

* **seconds to a D-opt**: how long a baseline must be flown to reach the D-optimality the
  planned flight reaches in its budget. The belief is propagated along the baseline with
  the planner's EKF covariance recursion (`mavsysid.planner.belief.propagate_steps`), the
  flight repeated back to back when it is not enough (a practitioner flies the same
  excitation again; the model is invariant to where the vehicle is), and the crossing of
  the target is interpolated in log D-opt;
* **seconds to 1 %**: the flight time after which every σ_j/θ_j is at most 1 %, from the
  estimator's σ over time or from a predicted belief.

The paper's convergence time (the median of the estimates within 5 % of the truth) is mostly
chance: the median of twenty ±50 % draws starts inside the 5 % band for about a third of
the parameters. It stays as a column only (`mavsysid.experiments.evaluation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.planner.belief import edge_samples, propagate_steps
from mavsysid.planner.search_setup import initial_covariance
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.linearization import ErrorStateModel
from mavsysid.vehicle.trajectory import Trajectory

__all__ = ["RELATIVE_SIGMA_TARGET", "BeliefHistory", "belief_history", "first_crossing",
           "seconds_to_dopt", "seconds_to_relative_sigma"]

#: The σ_j/θ_j every parameter must reach for `seconds_to_relative_sigma`.
RELATIVE_SIGMA_TARGET = 0.01


@dataclass(frozen=True)
class BeliefHistory:
    """The predicted θ belief over flight time.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Flight time, s (0 before the first measurement).
    dopt : ndarray, shape (K,)
        D-optimality det(Σ_θ)^(1/6), SI.
    sigma : ndarray, shape (K, 6)
        σ of each parameter, SI.
    """

    t: np.ndarray
    dopt: np.ndarray
    sigma: np.ndarray


def belief_history(config: VehicleConfig, trajectory: Trajectory, settings: PlannerSettings,
                   passes: int = 1) -> BeliefHistory:
    """The belief along ``trajectory`` flown ``passes`` times back to back.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle whose nominal θ linearises the model (the truth to evaluate a flight,
        the prior to see what a planner saw).
    trajectory : Trajectory
        The flight, starting and ending at rest.
    settings : PlannerSettings
        Measurement rate and prior σ (`mavsysid.planner.search_setup.initial_covariance`);
        with ``autopilot`` the belief follows the flight it is predicted to fly.
    passes : int
        How many times the flight is repeated.

    Returns
    -------
    BeliefHistory
        At the measurement rate, ``passes`` × duration long.
    """
    model = ErrorStateModel.for_vehicle(config)
    theta = config.theta
    states, n, dt = edge_samples(trajectory, config, theta, settings.measurement_rate,
                                 settings.autopilot)
    sigma = initial_covariance(model, config, settings)
    covs = [model.parameter_covariance_si(sigma)[None]]
    for _ in range(passes):
        history = propagate_steps(model, sigma, states, n, theta, dt)
        sigma = history[-1]
        covs.append(model.parameter_covariance_si(history[1:]))
    cov = np.concatenate(covs)
    sign, logdet = np.linalg.slogdet(cov)
    dopt = np.where(sign > 0, np.exp(logdet / 6.0), np.inf)
    t = dt * np.arange(cov.shape[0])
    return BeliefHistory(t, dopt, np.sqrt(np.diagonal(cov, axis1=1, axis2=2)))


def first_crossing(t: np.ndarray, values: np.ndarray, target: float) -> float:
    """First time ``values`` (positive, shape (K,)) falls to ``target``, interpolated in log.

    Returns
    -------
    float
        s; 0 when the first value is already at or below the target; NaN when never.
    """
    below = np.flatnonzero(values <= target)
    if below.size == 0:
        return float("nan")
    i = int(below[0])
    if i == 0:
        return float(t[0])
    y0, y1 = np.log(values[i - 1]), np.log(values[i])
    share = (y0 - np.log(target)) / (y0 - y1) if y0 > y1 else 1.0
    return float(t[i - 1] + share * (t[i] - t[i - 1]))


def seconds_to_dopt(config: VehicleConfig, trajectory: Trajectory, settings: PlannerSettings,
                    target: float, max_passes: int = 10) -> float:
    """Flight seconds of ``trajectory`` (repeated as needed) to reach D-opt ``target``.

    NaN when ``max_passes`` repetitions do not reach it (the figure is then more than
    ``max_passes`` × the duration).
    """
    passes = 1
    while True:
        history = belief_history(config, trajectory, settings, passes)
        seconds = first_crossing(history.t, history.dopt, target)
        if not np.isnan(seconds) or passes >= max_passes:
            return seconds
        passes = min(max_passes, 2 * passes)


def seconds_to_relative_sigma(t: np.ndarray, sigma: np.ndarray, theta: np.ndarray,
                              target: float = RELATIVE_SIGMA_TARGET) -> float:
    """First flight time at which every σ_j/|θ_j| ≤ ``target``, interpolated in log.

    Parameters
    ----------
    t : ndarray, shape (K,)
        Flight time, s.
    sigma : ndarray, shape (K, 6)
        σ over time, SI.
    theta : ndarray, shape (6,)
        The θ the σ are relative to (the truth in an evaluation).

    Returns
    -------
    float
        s; NaN when the flight ends before every parameter gets there.
    """
    worst = np.max(np.asarray(sigma, dtype=float) / np.abs(np.asarray(theta, dtype=float)),
                   axis=1)
    return first_crossing(np.asarray(t, dtype=float), worst, target)
