"""Tests of hidden effects in the MAVLink simulated vehicle's physics and truth log."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.simvehicle.physics import SimVehicle, TruthLog
from mavsysid.flight.simvehicle.reference import hold_target
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import parse_effect
from mavsysid.vehicle.rotation import quat_to_matrix


def _fly(tmp_path, specs, seconds=3.0, **meta):
    """Take off to 1 m and hover for ``seconds`` with hidden effects, logging the truth."""
    config = load_vehicle("firefly")
    log = TruthLog(tmp_path / "f", config, meta, seed=0, noise=False)
    vehicle = SimVehicle(config, config.theta, sensor_noise=False, truth_log=log,
                         effects=[hidden_effect(parse_effect(s)) for s in specs])
    vehicle.lift_off()
    hold_target(vehicle.target, np.array([0.3, 0.0, 1.0]), 0.0)
    for _ in range(round(seconds / 0.002)):
        vehicle.step(armed=True)
    log.finish("complete", {})
    return config, vehicle


def test_marker_offset_and_motor_lag_reach_pose_csv_and_telemetry(tmp_path):
    """pose.csv and the published pose carry p + R r; rotor speeds are the commands."""
    r = np.array([0.03, 0.0, -0.02])
    config, vehicle = _fly(tmp_path, [f"marker_offset:x={r[0]},z={r[2]}", "motor_lag:tau=0.04"])
    pose = read_pose_log(tmp_path / "f" / "pose.csv", config.rotor_count)
    truth = read_pose_log(tmp_path / "f" / "truth.csv", config.rotor_count)
    np.testing.assert_allclose(pose.position,
                               truth.position + quat_to_matrix(truth.quaternion) @ r, atol=2e-6)
    commands = np.genfromtxt(tmp_path / "f" / "truth.csv", delimiter=",", names=True)
    np.testing.assert_allclose(pose.rotor_speeds[:, 0], commands["n_cmd1"], atol=1e-3)
    position, _, speeds = vehicle.measured()
    np.testing.assert_allclose(position, vehicle.position + quat_to_matrix(
        vehicle.quaternion) @ r, atol=1e-12)
    np.testing.assert_allclose(speeds, vehicle.n_cmd)
    assert vehicle._tau == 0.04


def test_pose_delay_in_the_truth_log(tmp_path):
    """pose.csv at t holds the true pose at t − d (d a multiple of the 5 ms log period)."""
    config, _ = _fly(tmp_path, ["pose_delay:delay=0.02"])
    pose = read_pose_log(tmp_path / "f" / "pose.csv", config.rotor_count)
    truth = read_pose_log(tmp_path / "f" / "truth.csv", config.rotor_count)
    np.testing.assert_allclose(pose.position[4:], truth.position[:-4], atol=2e-6)
    assert np.abs(pose.position - truth.position).max() > 1e-3


def test_wind_pushes_the_hovering_sim_vehicle_downwind(tmp_path):
    """A hidden 2 m/s wind towards +x moves the hover point downwind (+x), not sideways."""
    _, calm = _fly(tmp_path / "a", [], seconds=6.0)
    _, windy = _fly(tmp_path / "b", ["wind:x=2"], seconds=6.0)
    shift = windy.position - calm.position
    assert shift[0] > 0.01
    assert abs(shift[1]) < 0.1 * shift[0]


@pytest.mark.parametrize("specs", [["wind:x=2", "motor_lag:tau=0.04"]])
def test_truth_log_meta_records_hidden_effects(tmp_path, specs):
    """The sim endpoint's meta lists hidden effects under truth.effects, flagged hidden."""
    from mavsysid.flight.simvehicle.endpoint import SimEndpoint, SimSettings

    config = load_vehicle("firefly")
    settings = SimSettings(truth_log=tmp_path / "t", duration=0.01,
                           hidden_effects=tuple(parse_effect(s) for s in specs))
    endpoint = SimEndpoint("udpout:127.0.0.1:9", config, settings)
    try:
        meta = read_meta(tmp_path / "t" / "meta.json")
    finally:
        endpoint.vehicle.truth_log.finish("complete", {})
        endpoint.link.close()
    assert [e["name"] for e in meta["truth"]["effects"]] == ["wind", "motor_lag"]
    assert all(e["hidden"] for e in meta["truth"]["effects"])
    assert meta["truth"]["motor_time_constant_s"] == 0.04
    assert meta["model_effects"] == []


def test_published_noise_depends_on_the_tick_not_on_what_else_was_measured():
    """Two seeded vehicles, one measured every tick and one every third: the same noise
    at the common ticks (a reply to a request must not shift the rest of the flight)."""
    config = load_vehicle("firefly")
    every, sparse = (SimVehicle(config, config.theta, seed=7) for _ in range(2))
    common = []
    for tick in range(2500):  # across a block boundary of the drawn noise
        a = every.measured()
        if tick % 3 == 0:
            common.append((a, sparse.measured()))
        every.step(armed=False)
        sparse.step(armed=False)
    assert len(common) > 800
    for a, b in common:
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    positions = np.array([a[0] for a, _ in common])
    assert np.std(positions[:, 0]) > 0.1 * config.noise.position_sigma  # noise is on
