"""Known model effects in the estimator's terms: acting speeds, corrected poses, a wrench.

A `ModelEffect` (`mavsysid.vehicle.model_effects`) enters the model through up to three channels;
the estimator turns a flight and a list of effects into `ModelTerms`, what the filter and
the batch refinement consume:

* ``rotor_speeds`` — the filter is driven by ``acting_rotor_speeds(t, n_logged)`` (applied
  first, on the log's own time grid, in the order the effects are given);
* ``pose`` — the poses are replaced by ``corrected_pose(t, p, q)``. A delay moves the
  measurement times to t' = t − d; the filter then runs on the corrected times and each
  pose is paired with the acting rotor speeds *interpolated* (linearly) at its corrected
  time. Poses whose corrected time falls before the first (or after the last) rotor-speed
  sample keep the end speed rather than being dropped: the sample count, and so the
  likelihood the effect fit compares across delays, stays the same for every delay;
* ``wrench`` — an extra body force and torque per sample (N, 6), linear between samples
  in the filter's RK4 step. The wrench depends on the state (v_B, ω, p, q) and on θ, but
  the catalogue defines it in numpy, once for truth and model, so it is evaluated on a
  `WrenchReference`: the states and final θ of a previous filter pass at the same
  effects. The effects are small corrections, so the error of holding their state
  dependence at the previous pass is second order; `reference_terms` iterates the passes
  until θ settles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.model_effects import EffectInputs, ModelEffect, total_wrench

__all__ = ["ModelTerms", "WrenchReference", "has_wrench", "in_model_terms", "model_terms"]


@dataclass(frozen=True)
class WrenchReference:
    """Where state-dependent effect wrenches are evaluated: a previous filter pass.

    Attributes
    ----------
    states : ndarray, shape (N, 13)
        Filtered model states [p, v_B, q, ω] at every sample.
    theta : ndarray, shape (6,)
        θ of that pass (its final estimate), SI.
    """

    states: np.ndarray
    theta: np.ndarray


@dataclass(frozen=True)
class ModelTerms:
    """A flight in the model's terms under some effects.

    Attributes
    ----------
    flight : FlightData
        Corrected times and poses, acting rotor speeds (N samples, as the log).
    wrench : ndarray, shape (N, 6)
        Extra body force (N) and torque (N·m) per sample; zeros without wrench effects.
    effects : tuple of ModelEffect
        The effects applied, with their values.
    """

    flight: FlightData
    wrench: np.ndarray
    effects: tuple[ModelEffect, ...]


def has_wrench(effects: Sequence[ModelEffect]) -> bool:
    """True when any of ``effects`` adds a force or torque (needs a `WrenchReference`)."""
    return any("wrench" in e.channels for e in effects)


def in_model_terms(flight: FlightData, effects: Sequence[ModelEffect]) -> FlightData:
    """The flight with the effects' rotor-speed and pose channels applied (see module doc)."""
    t, n = flight.t, flight.rotor_speeds
    for effect in effects:
        if "rotor_speeds" in effect.channels:
            n = effect.acting_rotor_speeds(t, n)
    t_model, p, q = t, flight.position, flight.quaternion
    for effect in effects:
        if "pose" in effect.channels:
            t_model, p, q = effect.corrected_pose(t_model, p, q)
    if t_model is not t and not np.array_equal(t_model, t):
        # np.interp holds the end values outside the log: the sample count stays fixed.
        n = np.column_stack([np.interp(t_model, t, n[:, i]) for i in range(n.shape[1])])
    if n is flight.rotor_speeds and t_model is t and p is flight.position:
        return flight
    return FlightData(np.asarray(t_model, float), np.asarray(p, float), np.asarray(q, float),
                      np.asarray(n, float), flight.source, flight.pose_source, flight.truth,
                      flight.warnings, flight.segment_starts, inputs=flight.inputs)


def _wrench(model_flight: FlightData, log_start: float, effects: Sequence[ModelEffect],
            config: VehicleConfig, reference: WrenchReference) -> np.ndarray:
    """The effects' wrench (N, 6) on the reference states, at the model's times."""
    x = reference.states
    if x.shape != (len(model_flight), 13):
        raise ValueError(f"reference states of shape ({len(model_flight)}, 13) expected, "
                         f"got {x.shape}")
    inputs = EffectInputs(
        t=model_flight.t - log_start, position=x[:, 0:3], quaternion=x[:, 6:10],
        velocity=x[:, 3:6], rates=x[:, 10:13], rotor_speeds=model_flight.rotor_speeds,
        theta=np.asarray(reference.theta, float),
        rotor_positions=np.asarray(config.rotor_positions, float),
        rotor_directions=np.asarray(config.rotor_directions, float))
    force, torque = total_wrench(list(effects), inputs)
    return np.ascontiguousarray(np.hstack([force, torque]))


def model_terms(
    flight: FlightData, effects: Sequence[ModelEffect], config: VehicleConfig,
    reference: WrenchReference | None = None,
) -> ModelTerms:
    """The flight and the wrench under ``effects`` (the model's view of the log).

    Parameters
    ----------
    flight : FlightData
        As logged.
    effects : sequence of ModelEffect
        Known effects with their values; empty for the paper's model.
    config : VehicleConfig
        Rotor geometry for the wrench.
    reference : WrenchReference, optional
        States and θ to evaluate wrench effects on; without one the wrench is zero (the
        first pass of `reference_terms` in `mavsysid.estimation.effect_fit`).

    Returns
    -------
    ModelTerms
    """
    effects = tuple(effects)
    model_flight = in_model_terms(flight, effects)
    if reference is None or not has_wrench(effects):
        wrench = np.zeros((len(flight), 6))
    else:
        wrench = _wrench(model_flight, float(flight.t[0]), effects, config, reference)
    return ModelTerms(model_flight, wrench, effects)
