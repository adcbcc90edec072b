"""The vehicle file's IMU: ``[imu] position`` and the IMU's ``[noise]`` keys."""

from __future__ import annotations

from pathlib import Path

import pytest
from mavsysid.vehicle.config import load_vehicle, save_vehicle
from mavsysid.vehicle.config_types import (
    ACCEL_BIAS_SIGMA,
    ACCEL_SIGMA,
    GYRO_BIAS_SIGMA,
    GYRO_SIGMA,
)

from mavsysid.errors import ConfigError
from tests.vehicle.test_config import MINIMAL


def _load(tmp_path: Path, text: str):
    path = tmp_path / "v.toml"
    path.write_text(text, encoding="utf-8")
    return load_vehicle(str(path))


def test_defaults_without_imu_keys(tmp_path: Path) -> None:
    config = _load(tmp_path, MINIMAL)
    assert config.imu_position is None
    noise = config.noise
    assert (noise.gyro_sigma, noise.accel_sigma, noise.gyro_bias_sigma,
            noise.accel_bias_sigma) == (GYRO_SIGMA, ACCEL_SIGMA, GYRO_BIAS_SIGMA,
                                        ACCEL_BIAS_SIGMA)


def test_imu_keys_read_and_saved(tmp_path: Path) -> None:
    text = MINIMAL + ("\n[imu]\nposition = [0.03, -0.01, 0.02]\n"
                      "\n[noise]\ngyro_sigma = 0.002\naccel_sigma = 0.03\n"
                      "gyro_bias_sigma = 0.001\naccel_bias_sigma = 0.05\n")
    config = _load(tmp_path, text)
    assert config.imu_position == pytest.approx((0.03, -0.01, 0.02))
    assert (config.noise.gyro_sigma, config.noise.accel_bias_sigma) == (0.002, 0.05)
    save_vehicle(config, tmp_path / "again.toml")
    again = load_vehicle(str(tmp_path / "again.toml"))
    assert again.imu_position == config.imu_position and again.noise == config.noise


@pytest.mark.parametrize(("extra", "match"), [
    ("\n[imu]\nposition = [0.1, 0.2]\n", r"\[imu\]\.position: an array of 3 finite numbers"),
    ("\n[imu]\nposition = [0.1, 0.2, 0.3]\noffset = 1\n", r"\[imu\]: a table with only"),
    ("\n[imu]\nposition = [0.1, nan, 0.3]\n", r"\[imu\]\.position"),
    ("\n[noise]\ngyro_sigma = -0.1\n", r"\[noise\]\.gyro_sigma: a number ≥ 0 \(rad/s\)"),
    ("\n[noise]\naccel_bias_sigma = \"big\"\n", r"\[noise\]\.accel_bias_sigma: a number"),
])
def test_bad_imu_keys_are_one_line_errors(tmp_path: Path, extra: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as caught:
        _load(tmp_path, MINIMAL + extra)
    assert "\n" not in str(caught.value)
