"""Tests of known model effects in vehicle configs: [effects.NAME] tables."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from mavsysid.vehicle.config import load_vehicle, save_vehicle, vehicle_to_toml
from mavsysid.vehicle.model_effects import GroundEffect, MotorLag, Wind

from mavsysid.errors import ConfigError

FIREFLY = Path(__file__).resolve().parents[2] / "vehicle" / "configs" / "firefly.toml"


def _with(tmp_path: Path, extra: str) -> Path:
    path = tmp_path / "vehicle.toml"
    path.write_text(FIREFLY.read_text(encoding="utf-8") + "\n" + extra, encoding="utf-8")
    return path


def test_effect_tables_are_read_in_file_order(tmp_path: Path) -> None:
    """[effects.NAME] tables become ModelEffects with their values; absent keys are 0."""
    config = load_vehicle(_with(tmp_path, "[effects.motor_lag]\ntau = 0.041\n\n"
                                          "[effects.wind]\nx = 1\n"))
    assert config.effects == (MotorLag(tau=0.041), Wind(x=1.0, y=0.0))
    assert isinstance(config.effects[1].values[0], float)


def test_config_without_effects_is_unchanged(tmp_path: Path) -> None:
    """No [effects]: an empty tuple, and the written TOML has no effects table."""
    config = load_vehicle("firefly")
    assert config.effects == ()
    assert "[effects" not in vehicle_to_toml(config)
    assert load_vehicle(_with(tmp_path, "")) == dataclasses.replace(
        config, source=str(tmp_path / "vehicle.toml"), name="firefly")


def test_effects_round_trip_through_save_vehicle(tmp_path: Path) -> None:
    """save_vehicle + load_vehicle gives back the same effects, bit for bit."""
    config = dataclasses.replace(load_vehicle("firefly"), effects=(
        MotorLag(tau=0.1 + 0.2), GroundEffect(rotor_radius=0.1), Wind(x=-1.5, y=2.0 / 3.0)))
    path = tmp_path / "copy.toml"
    save_vehicle(config, path)
    again = load_vehicle(path)
    assert again.effects == config.effects
    assert dataclasses.replace(again, source=config.source) == config


@pytest.mark.parametrize(("extra", "key", "detail"), [
    ("[effects.motro_lag]\ntau = 0.04\n", "[effects.motro_lag]",
     "did you mean [effects.motor_lag]?"),
    ("[effects.drag]\nk = 0.04\n", "[effects.drag]", "one of the known effects (body_drag,"),
    ("[effects.motor_lag]\ntua = 0.04\n", "[effects.motor_lag].tua",
     "did you mean [effects.motor_lag].tau?"),
    ("[effects.wind]\nz = 1\n", "[effects.wind].z", "one of the known keys (x, y)"),
    ("[effects.motor_lag]\ntau = \"0.04\"\n", "[effects.motor_lag].tau",
     "a number (s), got a string '0.04'"),
    ("[effects.motor_lag]\ntau = -0.04\n", "[effects.motor_lag].tau", "a number ≥ 0 (s)"),
    ("[effects.pose_delay]\ndelay = nan\n", "[effects.pose_delay].delay", "a finite number"),
    ("[effects]\nwind = 2\n", "[effects.wind]", "a table of the effect's parameters"),
    ("[efects.wind]\nx = 2\n", "[efects]", "did you mean [effects]?"),
])
def test_bad_effect_table_is_a_one_line_error(tmp_path: Path, extra: str, key: str,
                                              detail: str) -> None:
    """A bad effect name, key or value is one ConfigError line naming the key."""
    path = _with(tmp_path, extra)
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key}: ")
    assert detail in message
    assert "\n" not in message
