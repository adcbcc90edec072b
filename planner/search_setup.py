"""What a planning run needs before its search starts: the search's lumped measurement
model, the estimator's initial covariance and warm numba kernels (the request itself is
checked by `mavsysid.planner.plan_request`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from mavsysid.planner.belief import (
    apply_transfer_logdet,
    edge_samples,
    edge_transfer,
    propagate_final,
)
from mavsysid.planner.feasibility import check_segment
from mavsysid.planner.segments import Segment, VertexState, connect_free_end
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.linearization import E_THETA, ErrorStateModel, initial_state_sigma
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["initial_covariance", "search_model", "segment_trajectory", "warm_up"]


def segment_trajectory(segment: Segment) -> PiecewisePolynomial:
    """One segment as a one-piece trajectory."""
    return PiecewisePolynomial(np.array([segment.duration]), segment.position_coeffs[None],
                               segment.yaw_coeffs[None])


def search_model(config: VehicleConfig, settings: PlannerSettings) -> ErrorStateModel:
    """The model for search steps at the propagation rate: each step's measurement carries
    the information of measurement_rate / propagation_rate measurements."""
    weight = settings.measurement_rate / settings.propagation_rate
    nz = config.noise
    lumped = replace(config, noise=replace(nz, position_sigma=nz.position_sigma / np.sqrt(weight),
                                           attitude_sigma=nz.attitude_sigma / np.sqrt(weight)))
    return ErrorStateModel.for_vehicle(lumped)


def initial_covariance(model: ErrorStateModel, config: VehicleConfig,
                        settings: PlannerSettings) -> np.ndarray:
    """The estimator's initial covariance: state from the first poses, θ from the prior."""
    s = initial_state_sigma(config.noise.position_sigma, config.noise.attitude_sigma,
                            1.0 / settings.measurement_rate)
    diag = np.concatenate([np.full(3, v**2) for v in s] + [np.full(6, 0.0)])
    sigma = np.diag(diag)
    sigma[E_THETA, E_THETA] = settings.theta_covariance
    assert sigma.shape == (model.dim, model.dim)
    return sigma


def warm_up(config: VehicleConfig, settings: PlannerSettings) -> None:
    """Load (or compile) the numba kernels before the planning clock starts."""
    pose = settings.start_pose
    state = VertexState.hover(pose[:3], float(pose[3]))
    segment = connect_free_end(state, pose[:3] + [0.1, 0.0, 0.0], float(pose[3]), 1.0)
    check_segment(segment, config, np.asarray(settings.box, dtype=float))
    model = search_model(config, settings)
    states, n, dt = edge_samples(segment_trajectory(segment), config, config.theta,
                                 settings.propagation_rate, settings.autopilot)
    transfer = edge_transfer(model, states, n, config.theta, dt)
    apply_transfer_logdet(np.eye(model.dim), transfer)
    propagate_final(model, np.eye(model.dim), states, n, config.theta, dt)

