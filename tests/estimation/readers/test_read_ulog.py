"""Round trips of PX4 ULog files (minimal spec writer in conftest) through load_flight."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.vehicle.config import VehicleConfig

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]


@pytest.mark.parametrize(
    ("pose", "rotors", "pose_source", "rotor_atol"),
    [
        ("mocap", "esc", "motion_capture", 0.1),  # integer rpm: ±0.05 rad/s
        ("autopilot", "esc", "autopilot", 0.1),
        ("mocap", "motors", "motion_capture", 0.02),
        ("mocap", "outputs", "motion_capture", 0.02),
    ],
)
def test_ulog_round_trip(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                         ulog_writer: Callable[..., Path],
                         assert_matches_truth: Callable[..., None], pose: str, rotors: str,
                         pose_source: str, rotor_atol: float) -> None:
    """A NED/FRD ULog flight reads back in ENU/FLU, rad/s, on the pose times in the rotor span."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, pose=pose, rotors=rotors)
    data = load_flight(path, firefly)
    assert data.pose_source == pose_source
    assert data.source == str(path)
    rate = 100.0 if pose == "mocap" else 50.0
    expected_t = 20.0 + np.arange(400 if pose == "mocap" else 200) / rate
    # Rotor speeds cover [20.007, 23.987] s: pose samples outside are dropped.
    expected_t = expected_t[(expected_t >= 20.007) & (expected_t <= 23.987)]
    np.testing.assert_allclose(data.t, expected_t, atol=1e-9)
    assert_matches_truth(data, truth, rotor_atol)
    curve_notes = [w for w in data.warnings if "commanded, not measured" in w]
    assert len(curve_notes) == (rotors != "esc")
    assert len(data.warnings) == len(curve_notes)


def test_ulog_unused_motor_columns_are_dropped(tmp_path: Path, firefly: VehicleConfig,
                                               truth: Truth,
                                               ulog_writer: Callable[..., Path]) -> None:
    """actuator_motors columns that are NaN throughout are not rotors; NaN elsewhere is 0."""

    def stop_first_motor(topics: dict[str, list[dict[str, float]]]) -> None:
        for row in topics["actuator_motors"][:5]:
            row["control[0]"] = np.nan

    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, rotors="motors",
                       edit=stop_first_motor)
    data = load_flight(path, firefly)
    assert data.rotor_count == 6
    assert data.rotor_speeds[0, 0] == 0.0
