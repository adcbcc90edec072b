"""The offline simulator's IMU: the true reading against the truth differentiated, its noise
and biases against the σ and the biases it records, and a noise that leaves the pose's as
it was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.offline.effects import ConstantWrench
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.imu_sensor import ImuSensor
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.flight_log import TRUTH_COLUMNS
from mavsysid.formats.poselog import PoseLog, read_pose_log
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.rotation import quat_to_matrix

_LEVER = (0.04, -0.03, 0.02)  # m, body FLU: a visibly offset IMU


@pytest.fixture(scope="module")
def quad() -> VehicleConfig:
    return load_vehicle("quad_x")


@pytest.fixture(scope="module")
def flights(quad: VehicleConfig, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """8 s of the excitation at 500 Hz: noisy with an offset IMU, the same noise-free, and
    the same without the IMU."""
    root = tmp_path_factory.mktemp("imu")
    trajectory = excitation_trajectory(ExcitationSpec(duration=8.0))
    runs = {"noisy": SimulationSettings(log_rate=500.0, seed=3, imu_position=_LEVER),
            "clean": SimulationSettings(log_rate=500.0, seed=3, sensor_noise=False,
                                        imu_position=_LEVER),
            "no_imu": SimulationSettings(log_rate=500.0, seed=3, imu=False)}
    wind = [ConstantWrench(force=np.array([0.3, -0.2, 0.1]))]  # an extra force the IMU feels
    for name, settings in runs.items():
        Simulator(quad, settings=settings, effects=wind).run(trajectory, root / name)
    return {name: root / name for name in runs}


def _truth(directory: Path, quad: VehicleConfig) -> PoseLog:
    return read_pose_log(directory / "truth.csv", quad.rotor_count)


def _central(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """d/dt by central differences at the inner samples."""
    return (values[2:] - values[:-2]) / (t[2:] - t[:-2])[:, None]


def test_true_reading_is_the_motion_differentiated(flights: dict[str, Path],
                                                   quad: VehicleConfig) -> None:
    """gyro = ω, and the specific force at the IMU = Rᵀ(a − g) + ω̇ × p + ω × (ω × p), with
    a and ω̇ differentiated from the true trajectory (independent of the force model)."""
    truth = _truth(flights["clean"], quad)
    w = np.column_stack([truth.extra[c] for c in TRUTH_COLUMNS[3:]])
    np.testing.assert_allclose(truth.gyro, w, atol=1e-7)
    R = quat_to_matrix(truth.quaternion)
    v_body = np.column_stack([truth.extra[c] for c in TRUTH_COLUMNS[:3]])
    v_world = np.einsum("nij,nj->ni", R, v_body)
    a_world = _central(truth.t, v_world)
    f_cog = np.einsum("nji,nj->ni", R[1:-1], a_world + [0.0, 0.0, GRAVITY])
    w_dot = _central(truth.t, w)
    p = np.array(_LEVER)
    expected = (f_cog + np.cross(w_dot, p) + np.cross(w[1:-1], np.cross(w[1:-1], p)))
    error = truth.accel[1:-1] - expected
    scale = np.std(truth.accel[1:-1], axis=0)
    assert np.all(np.sqrt(np.mean(error**2, axis=0)) < 0.01 * np.maximum(scale, 1.0)), (
        np.sqrt(np.mean(error**2, axis=0)), scale)
    # Hovering at the start it reads +g up: the thrust, not gravity.
    np.testing.assert_allclose(truth.accel[0], [0.0, 0.0, GRAVITY], atol=0.05)


def test_measured_reading_is_truth_plus_bias_and_noise(flights: dict[str, Path],
                                                       quad: VehicleConfig) -> None:
    pose = read_pose_log(flights["noisy"] / "pose.csv", quad.rotor_count)
    truth = _truth(flights["noisy"], quad)
    imu = read_meta(flights["noisy"] / "meta.json")["truth"]["imu"]
    assert imu["position_m"] == pytest.approx(list(_LEVER))
    for measured, true, bias, sigma in ((pose.gyro, truth.gyro, imu["gyro_bias_rad_s"],
                                         quad.noise.gyro_sigma),
                                        (pose.accel, truth.accel, imu["accel_bias_m_s2"],
                                         quad.noise.accel_sigma)):
        error = measured - true
        n = error.shape[0]
        np.testing.assert_allclose(error.mean(axis=0), bias, atol=4 * sigma / np.sqrt(n))
        np.testing.assert_allclose(error.std(axis=0), sigma, rtol=0.1)
        assert np.abs(np.corrcoef(error[1:, 0], error[:-1, 0])[0, 1]) < 0.1  # white
    assert np.any(np.abs(imu["gyro_bias_rad_s"]) > 0) and np.any(np.abs(imu["accel_bias_m_s2"]))
    clean = read_pose_log(flights["clean"] / "pose.csv", quad.rotor_count)
    np.testing.assert_allclose(clean.accel, truth.accel, atol=1e-6)


def test_the_imu_leaves_the_pose_noise_as_it_was(flights: dict[str, Path],
                                                 quad: VehicleConfig) -> None:
    with_imu = read_pose_log(flights["noisy"] / "pose.csv", quad.rotor_count)
    without = read_pose_log(flights["no_imu"] / "pose.csv", quad.rotor_count)
    np.testing.assert_array_equal(with_imu.position, without.position)
    np.testing.assert_array_equal(with_imu.quaternion, without.quaternion)
    assert without.gyro is None and "imu" not in read_meta(
        flights["no_imu"] / "meta.json")["truth"]


def test_noise_by_sample_index_and_resting_reading(quad: VehicleConfig) -> None:
    """A sample's noise is the same whatever else was measured; at rest on the ground the
    reading is the reaction to gravity, seen in the body."""
    a, b = ImuSensor(quad, 5, True), ImuSensor(quad, 5, True)
    zero = np.zeros(3)
    first = [a.measure(zero, zero, i) for i in (0, 1500, 7)]
    assert np.array_equal(b.measure(zero, zero, 7)[0], first[2][0])
    assert np.array_equal(b.measure(zero, zero, 1500)[1], first[1][1])
    assert not np.array_equal(first[0][0], first[2][0])
    x = np.zeros(13)
    x[6:10] = [np.cos(0.2), np.sin(0.2), 0.0, 0.0]  # rolled 0.4 rad about x
    gyro, accel = a.ideal(x, np.zeros(quad.rotor_count), quad.theta, landed=True)
    np.testing.assert_allclose(accel, GRAVITY * np.array([0.0, np.sin(0.4), np.cos(0.4)]),
                               atol=1e-12)
    assert not gyro.any()
