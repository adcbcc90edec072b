"""A seventh estimated quantity, declared here with its model term and nothing else: it
runs through the filter, the batch, the force and torque balance and the answer.

The quantity is a thrust drift c_T(t) = c_T (1 + r t) (a battery sagging), whose term is
the rotor wrench times t per unit r. The flight hides that drift in the simulator's truth
(the catalogue's ``thrust_drift`` acting on the true vehicle); without the quantity θ
absorbs it, with it r is answered with an interval that covers the truth.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation import (
    DETERMINED,
    EstimatorSettings,
    estimate,
    estimate_parameters,
    fit_wrench_balance,
    result_to_json,
)
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle
from mavsysid.vehicle.effect_base import EffectInputs, rotor_force_wrench
from mavsysid.vehicle.model_effects import effect_from_values
from mavsysid.vehicle.parameters import EstimatedQuantity, QuantityTerm

from tests.support.hidden import hidden_flight

#: The drift hidden in the truth: −8 % of c_T over 30 s.
RATE = -0.08 / 30.0


class ThrustDriftTerm(QuantityTerm):
    """The rotors' wrench times the time since the flight started, per unit drift rate."""

    def wrench_basis(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        force, torque = rotor_force_wrench(inputs)
        return force * inputs.t[:, None], torque * inputs.t[:, None]


DRIFT = EstimatedQuantity("thrust_drift_rate", "1/s", "relative change of c_T per second",
                          nominal=0.0, prior_sigma=0.01, term=ThrustDriftTerm())


@pytest.fixture(scope="module")
def drifting_flight(tmp_path_factory: pytest.TempPathFactory):
    """A 30 s Firefly flight (100 Hz pose) whose true c_T drifts by `RATE`."""
    config = load_vehicle("firefly")
    flight = hidden_flight(config, tmp_path_factory.mktemp("drift"),
                           [effect_from_values("thrust_drift", {"rate": RATE})], seed=3)
    return config, flight


def test_the_quantity_runs_through_filter_and_batch(drifting_flight) -> None:
    """The filter and batch estimate the drift beside θ, within its σ."""
    config, flight = drifting_flight
    result = estimate_parameters(flight, replace(config, extra_quantities=(DRIFT,)),
                                 EstimatorSettings(guard=False))
    final = result.final
    assert final.names == (*PARAMETER_NAMES, DRIFT.name)
    assert final.value.shape == (7,) and final.covariance.shape == (7, 7)
    assert result.history.theta.shape[1] == 7
    assert abs(final.value[6] - RATE) <= 3.0 * final.sigma[6]
    assert final.sigma[6] < 0.2 * abs(RATE)


def test_the_quantity_runs_through_the_balance(drifting_flight) -> None:
    """The force and torque balance determines the drift and covers it."""
    config, flight = drifting_flight
    balance = fit_wrench_balance(flight, replace(config, extra_quantities=(DRIFT,)))
    assert balance.estimate.names[-1] == DRIFT.name and balance.determined[6]
    value, sigma = balance.estimate.value[6], balance.estimate.sigma[6]
    assert abs(value - RATE) <= 3.0 * sigma and sigma < 0.25 * abs(RATE)
    assert "thrust_drift_rate" in balance.as_dict()["nuisance"]


def test_the_answer_names_it_and_keeps_theta_honest(drifting_flight) -> None:
    """The answer carries the drift by name, and with it c_T's interval covers the truth,
    where without it the drift biases c_T beyond its interval."""
    config, flight = drifting_flight
    truth = np.asarray(flight.true_theta)
    with_drift = replace(config, extra_quantities=(DRIFT,))
    result = estimate(flight, with_drift)
    final = result.final
    assert result.status[6] == DETERMINED
    assert abs(final.value[6] - RATE) <= 3.0 * final.sigma[6]
    assert abs(final.value[0] - truth[0]) <= 3.0 * final.sigma[0]
    doc = result_to_json(result, with_drift, flight.source)
    assert math.isclose(doc["nuisance"][DRIFT.name]["value"], final.value[6])
    assert list(doc["parameters"]) == list(PARAMETER_NAMES)
    without = estimate(flight, config).final
    assert abs(without.value[0] - truth[0]) > 3.0 * without.sigma[0]
