"""The multirotor model shared by every stage of mavsysid.

Configurations (`load_vehicle`), the dynamics ẋ = f(x, u, θ) (`state_derivative`), rotor
allocation, differential flatness (`flat_to_state`), the error-state linearisation used
by both the planner and the estimator (`ErrorStateModel`), the estimated quantities
(`PAPER_THETA` and nuisance `EstimatedQuantity`s) and trajectories.
"""

from __future__ import annotations

from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv, rotor_speeds_squared
from mavsysid.vehicle.config import (
    PARAMETER_NAMES,
    SHIPPED_VEHICLES,
    Parameters,
    VehicleConfig,
    load_vehicle,
    save_vehicle,
)
from mavsysid.vehicle.dynamics import STATE_DIM, hover_state, state_derivative
from mavsysid.vehicle.flatness import FlatState, flat_to_state
from mavsysid.vehicle.linearization import ErrorStateModel
from mavsysid.vehicle.parameters import PAPER_THETA, EstimatedQuantity, QuantityTerm
from mavsysid.vehicle.trajectory import FlatOutputs, PiecewisePolynomial, Trajectory

__all__ = [
    "PAPER_THETA",
    "PARAMETER_NAMES",
    "SHIPPED_VEHICLES",
    "STATE_DIM",
    "ErrorStateModel",
    "EstimatedQuantity",
    "FlatOutputs",
    "FlatState",
    "Parameters",
    "PiecewisePolynomial",
    "QuantityTerm",
    "Trajectory",
    "VehicleConfig",
    "allocation_matrix",
    "allocation_pinv",
    "flat_to_state",
    "hover_state",
    "load_vehicle",
    "rotor_speeds_squared",
    "save_vehicle",
    "state_derivative",
]
