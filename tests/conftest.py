"""Shared fixtures: shipped vehicles, an aggressive reference trajectory, synthetic logs.

The synthetic flight and its log writers (`tests.support.synthetic_logs`) serve the format
tests and the reader tests.
"""

from __future__ import annotations

import os

# Every run of the suite compiles the numba kernels afresh (their cache is keyed by the
# sources), in each worker. LLVM's level 1 compiles them in about two thirds of level 3's
# time and runs the suite's short flights as fast; without fastmath every level keeps IEEE
# semantics, so the numbers are the same to the bit. A user's runs keep numba's default.
os.environ["NUMBA_OPT"] = os.environ.get("NUMBA_OPT", "1")

import numpy as np
import pytest
from mavsysid.vehicle.config import SHIPPED_VEHICLES, VehicleConfig, load_vehicle
from mavsysid.vehicle.trajectory import PiecewisePolynomial

pytest_plugins = ["tests.support.synthetic_logs"]


@pytest.fixture(params=SHIPPED_VEHICLES)
def any_vehicle(request: pytest.FixtureRequest) -> VehicleConfig:
    """Each shipped vehicle in turn: a 30 g, a 1 kg and a 1.6 kg multirotor."""
    return load_vehicle(request.param)


@pytest.fixture
def firefly() -> VehicleConfig:
    """The reference vehicle."""
    return load_vehicle("firefly")


def _aggressive(duration: float = 3.0) -> PiecewisePolynomial:
    """A 3 s figure with > 1 g lateral acceleration and > 3 rad/s body rates.

    x = A sin(ω t) with A ω² = 1.1 g, y and z small oscillations, yaw a small slow swing
    (the Firefly has little yaw authority);
    Hermite-matched degree-9 segments every 0.25 s (so it is a polynomial trajectory).
    """
    w = np.array([3.0, 2.1, 1.7])
    a = np.array([1.2, 0.35, 0.15])
    phase = np.array([0.0, 0.4, 1.1])
    times = np.linspace(0.0, duration, 13)
    pos = np.empty((times.size, 5, 3))
    for m in range(5):
        pos[:, m, :] = a * w**m * np.sin(np.outer(times, w) + phase + m * np.pi / 2)
    pos[:, 0, 2] += 1.5
    wy, ay = 1.3, 0.1
    yaw = np.stack([ay * wy**m * np.sin(wy * times + m * np.pi / 2) for m in range(3)], axis=1)
    return PiecewisePolynomial.from_waypoints(times, pos, yaw)


@pytest.fixture
def aggressive_trajectory() -> PiecewisePolynomial:
    """A short aggressive polynomial trajectory within the Firefly's actuator limits."""
    return _aggressive()
