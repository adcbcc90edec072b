"""The multirotor model shared by every stage of mavsysid.

Configurations (`load_vehicle`), the dynamics ẋ = f(x, u, θ) (`state_derivative`), rotor
allocation, differential flatness (`flat_to_state`), the error-state linearisation used
by both the planner and the estimator (`ErrorStateModel`), trajectories, and the pose-log
file format.
"""

from __future__ import annotations

from vehicle.compiled_cache import configure_numba_cache

configure_numba_cache()  # before any module imports numba

from vehicle.allocation import allocation_matrix, allocation_pinv, rotor_speeds_squared
from vehicle.config import (
    PARAMETER_NAMES,
    SHIPPED_VEHICLES,
    Parameters,
    VehicleConfig,
    load_vehicle,
    save_vehicle,
)
from vehicle.dynamics import STATE_DIM, hover_state, state_derivative
from vehicle.errors import ConfigError, InputError, JobFailedError, LogFormatError
from vehicle.flatness import FlatState, flat_to_state
from vehicle.linearization import ERROR_DIM, ErrorStateModel
from vehicle.poselog import PoseLog, read_pose_log
from vehicle.trajectory import FlatOutputs, PiecewisePolynomial, Trajectory

__all__ = [
    "ERROR_DIM",
    "PARAMETER_NAMES",
    "SHIPPED_VEHICLES",
    "STATE_DIM",
    "ConfigError",
    "ErrorStateModel",
    "FlatOutputs",
    "FlatState",
    "InputError",
    "JobFailedError",
    "LogFormatError",
    "Parameters",
    "PiecewisePolynomial",
    "PoseLog",
    "Trajectory",
    "VehicleConfig",
    "allocation_matrix",
    "allocation_pinv",
    "flat_to_state",
    "hover_state",
    "load_vehicle",
    "read_pose_log",
    "rotor_speeds_squared",
    "save_vehicle",
    "state_derivative",
]
