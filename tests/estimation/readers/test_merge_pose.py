"""Merging an external motion-capture pose with a flight log: clock offset and result."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.rotation import quat_exp, quat_multiply

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]

OFFSET = 1234.5678  # s: t_log = t_mocap + OFFSET
PERIOD = 0.01  # s, motion-capture sample period


def _write_mocap(path: Path, truth: Truth, noisy: bool = True) -> Path:
    """100 Hz motion capture of t_log 19..25 s (longer than the log) on its own clock."""
    rng = np.random.default_rng(7)
    t_log = 19.0 + PERIOD * np.arange(600)
    x = truth(t_log)
    p, q = x["position"], x["quaternion"]
    if noisy:  # docs/architecture.md: 0.5 mm, 0.1° (σ)
        p = p + rng.normal(0.0, 0.0005, p.shape)
        q = quat_multiply(q, quat_exp(rng.normal(0.0, np.radians(0.1), (q.shape[0], 3))))
    table = np.column_stack([t_log - OFFSET, p, q])
    np.savetxt(path, table, delimiter=",", fmt="%.9f", header="t,x,y,z,qw,qx,qy,qz",
               comments="")
    return path


@pytest.mark.parametrize(("log_pose", "method"), [
    ("autopilot", "body angular-rate magnitude"),
    (None, "Σ n²"),
])
def test_found_offset_is_within_one_sample(tmp_path: Path, firefly: VehicleConfig,
                                           truth: Truth, ulog_writer: Callable[..., Path],
                                           log_pose: str | None, method: str) -> None:
    """A mocap file shifted by a known clock offset is aligned to within one sample period."""
    log = ulog_writer(tmp_path / "flight.ulg", truth, firefly, pose=log_pose)
    mocap = _write_mocap(tmp_path / "mocap.csv", truth)
    data = load_flight(log, firefly, pose=mocap)
    info = [w for w in data.warnings if w.startswith("info:")]
    assert len(info) == 1 and method in info[0]
    found = float(info[0].split("offset ")[1].split(" s")[0])
    assert abs(found - OFFSET) < PERIOD
    assert data.pose_source == "motion_capture"
    assert data.source == f"{log} + pose {mocap}"
    # The pose is the mocap's (shifted by the found offset), the rotor speeds the log's.
    np.testing.assert_allclose(data.position, truth(data.t + OFFSET - found)["position"],
                               atol=0.003)
    np.testing.assert_allclose(data.rotor_speeds, truth(data.t)["rotor_speeds"], atol=0.1)
    assert data.t[0] >= 20.0 and data.t[-1] <= 24.0


def test_given_offset_is_used_as_is(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                                    ulog_writer: Callable[..., Path],
                                    assert_matches_truth: Callable[..., None]) -> None:
    """With time_offset given, mocap times shift by exactly it and the info line says so."""
    log = ulog_writer(tmp_path / "flight.ulg", truth, firefly, pose="autopilot")
    mocap = _write_mocap(tmp_path / "mocap.csv", truth, noisy=False)
    data = load_flight(log, firefly, pose=mocap, time_offset=OFFSET)
    assert any(w.startswith("info:") and w.endswith("(given)") for w in data.warnings)
    assert_matches_truth(data, truth, 0.1, pose_atol=1e-6)


def test_commanded_rotor_speeds_keep_the_curves_uncertainty_under_a_merged_pose(
        tmp_path: Path, firefly: VehicleConfig, truth: Truth,
        ulog_writer: Callable[..., Path]) -> None:
    """Motor outputs through the curve, the pose from motion capture: c_T still carries the
    curve's σ (the merged flight is the log's rotor speeds, not measured ones)."""
    log = ulog_writer(tmp_path / "flight.ulg", truth, firefly, pose="autopilot",
                      rotors="outputs")
    mocap = _write_mocap(tmp_path / "mocap.csv", truth, noisy=False)
    alone = load_flight(log, firefly)
    merged = load_flight(log, firefly, pose=mocap, time_offset=OFFSET)
    assert alone.rotor_scale_sigma == firefly.motor.curve_sigma > 0.0
    assert merged.rotor_scale_sigma == alone.rotor_scale_sigma
    measured = ulog_writer(tmp_path / "esc.ulg", truth, firefly, pose="autopilot")
    assert load_flight(measured, firefly, pose=mocap, time_offset=OFFSET).rotor_scale_sigma == 0.0
