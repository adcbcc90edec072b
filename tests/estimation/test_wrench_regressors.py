"""The balance rows reproduce the simulator's physics at the true θ (same laws, same signs)."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.balance.rows import FORCE_COEFFICIENTS, BalanceBuilder
from mavsysid.estimation.balance.theta import coefficients_from_theta
from mavsysid.estimation.results import Band
from mavsysid.estimation.signals import uniform_segments
from mavsysid.vehicle.config import load_vehicle

SPLIT = len(FORCE_COEFFICIENTS)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_true_theta_balances_the_rows(simulate_flight, seed):
    """The measured side regressed on the model at the true θ has slope 1 on every axis.

    One slope per axis group, fitted by least squares: 1 within 2 % (c_T's row within
    0.1 %) if the columns carry the model's signs, rotor order and units, and a parameter
    20 % off moves its axis' slope by far more.
    """
    config = load_vehicle("micro_quad")
    flight = simulate_flight(config, seed, duration=20.0, log_rate=500.0)
    (segment,) = uniform_segments(flight, 2.0)
    band = Band(0.3, 3.0)
    truth = np.asarray(flight.true_theta)
    rows = BalanceBuilder(segment, config, 0.15).rows(0.0, truth[1], band, band)

    def slopes(theta: np.ndarray) -> np.ndarray:
        b = coefficients_from_theta(theta)
        model = np.hstack([rows.force_columns @ b[:SPLIT], rows.torque_columns @ b[SPLIT:]])
        measured = np.hstack([rows.force, rows.torque])
        return np.sum(model * measured, axis=0) / np.sum(model * model, axis=0)

    at_truth = slopes(truth)
    assert abs(at_truth[2] - 1.0) < 1e-3, at_truth
    assert np.all(np.abs(at_truth[3:] - 1.0) < 0.02), at_truth
    for k, axis in ((0, 2), (3, 3), (4, 4), (2, 5)):
        wrong = truth.copy()
        wrong[k] *= 1.2
        assert abs(slopes(wrong)[axis] - 1.0) > 0.1, (k, slopes(wrong))
