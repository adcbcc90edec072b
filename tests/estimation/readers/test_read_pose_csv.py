"""mavsysid pose logs (pose.csv) through load_flight: data, truth from meta.json, checks."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.formats.poselog import PoseLog, write_pose_log
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

from mavsysid.errors import LogFormatError

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]
TRUTH = {"parameters": {"c_T": 8.6e-6, "c_D": 0.018, "c_M": 1.4e-7, "j_x": 0.035,
                        "j_y": 0.046, "j_z": 0.098}}


def _write(directory: Path, truth: Truth, scale: float = 1.0,
           meta: dict[str, Any] | None = None) -> Path:
    t = np.arange(300) / 100.0
    x = truth(t)
    log = PoseLog(t, x["position"], x["quaternion"], scale * x["rotor_speeds"])
    path = write_pose_log(directory / "pose.csv", log)
    if meta is not None:
        (directory / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
    return path


@pytest.mark.parametrize(("meta", "has_truth"), [
    ({"simulated": True, "truth": TRUTH}, True),
    ({"simulated": False, "truth": TRUTH}, False),
    (None, False),
])
def test_pose_csv_round_trip_with_truth(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                                        assert_matches_truth: Callable[..., None],
                                        meta: dict[str, Any] | None, has_truth: bool) -> None:
    """A pose.csv reads back unchanged; meta.json's truth is attached only if simulated."""
    path = _write(tmp_path, truth, meta=meta)
    data = load_flight(path, firefly)
    assert data.pose_source == "motion_capture"
    np.testing.assert_allclose(data.t, np.arange(300) / 100.0, atol=1e-9)
    assert_matches_truth(data, truth, 1e-3, pose_atol=1e-6)
    assert data.warnings == ()
    if has_truth:
        np.testing.assert_allclose(data.true_theta, [8.6e-6, 0.018, 1.4e-7, 0.035, 0.046, 0.098])
    else:
        assert data.truth is None


@pytest.mark.parametrize(("scale", "says"), [
    (60.0 / (2.0 * np.pi), "look like rpm"),
    (1.0 / (2.0 * np.pi), "look like rev/s"),
    (1.0 / 838.0, "normalised motor outputs"),
    (0.0, "zero throughout"),
    (3.0, "not within a factor 5"),
])
def test_rotor_speeds_in_a_wrong_unit_are_named(tmp_path: Path, firefly: VehicleConfig,
                                                truth: Truth, scale: float, says: str) -> None:
    """Rotor speeds far from hover thrust fail in one line saying which unit they look like."""
    path = _write(tmp_path, truth, scale=scale)
    with pytest.raises(LogFormatError) as info:
        load_flight(path, firefly)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    assert says in message


def test_pose_csv_of_another_vehicle_names_both_counts(tmp_path: Path, firefly: VehicleConfig,
                                                       truth: Truth) -> None:
    """A 6-rotor pose log read with a 4-rotor config fails naming 4 and the 6 found."""
    path = _write(tmp_path, truth)
    with pytest.raises(LogFormatError, match=r"expected 4 rotor speed columns .* found 6"):
        load_flight(path, load_vehicle("quad_x"))
