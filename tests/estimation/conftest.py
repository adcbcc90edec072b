"""Simulated flights for the estimation tests (real simulator, real pose logs on disk)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.flight import FlightData
from mavsysid.flight.offline.effects import TruthEffect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import VehicleConfig

SimulateFlight = Callable[..., FlightData]


def _draw_prior(config: VehicleConfig, seed: int, spread: float = 0.5) -> VehicleConfig:
    rng = np.random.default_rng(10_000 + seed)
    return config.with_parameters(config.theta * (1.0 + rng.uniform(-spread, spread, 6)))


@pytest.fixture
def prior_config() -> Callable[..., VehicleConfig]:
    """The config with its nominal θ drawn ±50 % around the truth (seeded): the prior."""
    return _draw_prior


@pytest.fixture
def simulate_flight(tmp_path: Path) -> SimulateFlight:
    """Fly the built-in excitation in the simulator and read the pose log back."""

    def run(config: VehicleConfig, seed: int, duration: float = 30.0,
            effects: Sequence[TruthEffect] = (), log_rate: float = 100.0,
            control_rate: float = 500.0) -> FlightData:
        directory = tmp_path / f"{config.name}-{seed}-{duration:g}-{len(effects)}"
        settings = SimulationSettings(seed=seed, log_rate=log_rate, control_rate=control_rate)
        Simulator(config, settings=settings, effects=list(effects)).run(
            excitation_trajectory(ExcitationSpec(duration=duration)), directory)
        log = read_pose_log(directory / "pose.csv", config.rotor_count)
        truth = read_meta(directory / "meta.json")["truth"]
        return FlightData(log.t, log.position, log.quaternion, log.rotor_speeds,
                          str(directory / "pose.csv"), truth=truth)

    return run


@pytest.fixture
def with_noise() -> Callable[[VehicleConfig, float, float], VehicleConfig]:
    """A config with explicit force and moment noise densities."""

    def make(config: VehicleConfig, force: float, moment: float) -> VehicleConfig:
        return replace(config, noise=replace(config.noise, force_density=force,
                                             moment_density=moment))

    return make
