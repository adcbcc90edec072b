"""A filter run that diverges on degenerate input ends in one JobFailedError line."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.constants import GRAVITY

from mavsysid.errors import JobFailedError


def _hover_log(rotor_speeds: list[float], n: int = 400) -> FlightData:
    """A vehicle logged as still at 1 m while its rotors spin at ``rotor_speeds``."""
    t = np.arange(n) * 0.01
    position = np.tile([0.0, 0.0, 1.0], (n, 1))
    quaternion = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return FlightData(t, position, quaternion, np.tile(rotor_speeds, (n, 1)), "degenerate.csv")


def _run(flight: FlightData) -> None:
    config = load_vehicle("quad_x")
    prior = ParameterEstimate(config.theta, np.diag((0.5 * config.theta) ** 2))
    # A huge measurement σ: the updates cannot hold the state, as with a log the model
    # cannot follow (wrong vehicle, rotor order or motor curve).
    ParameterEKF(config, prior, (1e3, 3.0)).run(flight, (0.003, 0.5, 0.03, 0.5))


def test_diverging_filter_is_one_line_job_failure() -> None:
    with pytest.raises(JobFailedError) as info:
        _run(_hover_log([1e5, 0.0, 1e5, 0.0]))
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("degenerate.csv: the parameter filter diverged")


def test_same_log_with_plausible_rotor_speeds_runs() -> None:
    """The control: the same set-up with hover speeds does not diverge."""
    config = load_vehicle("quad_x")
    hover = float(np.sqrt(config.mass * GRAVITY / (4 * config.parameters.c_T)))
    _run(_hover_log([hover] * 4))
