"""Tests of θ re-estimated with the effects the diagnosis names
(`mavsysid.pipeline.auto_effects`) and of ``mavsysid estimate --auto-effects``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import estimate_parameters
from mavsysid.estimation.flight import FlightData
from mavsysid.pipeline.auto_effects import estimate_with_named_effects
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from mavsysid.vehicle.model_effects import effect_from_values

from mavsysid.cli import main
from tests.support.hidden import HIDDEN_MAGNITUDES, hidden_flight

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def config() -> VehicleConfig:
    return load_vehicle("firefly")


@pytest.fixture(scope="module")
def prior(config: VehicleConfig) -> VehicleConfig:
    """The Firefly with its θ drawn ±30 % around the truth (seeded)."""
    rng = np.random.default_rng(18)
    return config.with_parameters(config.theta * (1.0 + rng.uniform(-0.3, 0.3, 6)))


@pytest.fixture(scope="module")
def wind_flight(tmp_path_factory: pytest.TempPathFactory, config: VehicleConfig) -> FlightData:
    """30 s with a hidden steady wind of 2 m/s (`HIDDEN_MAGNITUDES`)."""
    wind = effect_from_values("wind", HIDDEN_MAGNITUDES["wind"])
    return hidden_flight(config, tmp_path_factory.mktemp("wind"), [wind], seed=3)


def _error(value: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.abs(value / truth - 1.0)


def test_hidden_wind_is_named_and_theta_gets_closer(wind_flight, config, prior):
    """Wind is named (with a note); θ is closer to the truth than the config-model estimate."""
    plain = estimate_parameters(wind_flight, prior)
    result, named = estimate_with_named_effects(wind_flight, prior)
    assert "wind" in [e.name for e in named]
    assert "wind" in [e.name for e in result.effects]
    assert any("named wind" in n for n in result.notes)
    truth = config.theta
    before, after = _error(plain.final.value, truth), _error(result.final.value, truth)
    assert np.max(after) < np.max(before)
    assert np.sum(after) < np.sum(before)


def test_clean_flight_names_nothing(tmp_path, config, prior):
    """Without a hidden effect nothing is named and the model stays the config's."""
    flight = hidden_flight(config, tmp_path / "clean", seed=4)
    result, named = estimate_with_named_effects(flight, prior)
    assert named == ()
    assert result.effects == ()
    assert any("named no effect" in n for n in result.notes)
    assert np.all(_error(result.final.value, config.theta) < 0.05)


def test_auto_effects_option_names_wind(wind_flight, tmp_path, capsys):
    """``--auto-effects`` exits 0 and writes the named wind into the JSON; without it the
    model has no effects."""
    log = Path(wind_flight.source)
    with_auto, without = tmp_path / "auto.json", tmp_path / "plain.json"
    assert main(["estimate", str(log), "--vehicle", "firefly", "-o", str(with_auto),
                 "--auto-effects", "-q"]) == 0
    assert main(["estimate", str(log), "--vehicle", "firefly", "-o", str(without), "-q"]) == 0
    capsys.readouterr()
    auto, plain = json.loads(with_auto.read_text()), json.loads(without.read_text())
    assert "wind" in json.dumps(auto.get("effects", {}))
    assert "wind" not in json.dumps(plain.get("effects", {}))
    assert set(auto["parameters"]) == set(PARAMETER_NAMES)
