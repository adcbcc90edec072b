"""The force and torque balance on the IMU: the gyro's one derivative, the accelerometer."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.answer import with_imu_quantities
from mavsysid.estimation.balance.fit import fit_wrench_balance
from mavsysid.estimation.filter.estimator import EstimatorSettings
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import prior_from_config
from mavsysid.estimation.signals import (
    SmootherSettings,
    convolve_columns,
    imu_segments,
    rate_kernel,
    savgol_kernel,
)
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

#: The prior 30 % off the truth, as the benchmarks draw it.
PRIOR_FACTORS = np.array([1.3, 0.7, 1.3, 0.7, 0.7, 0.7])


def test_rate_kernel_is_what_differentiating_a_rate_does_to_its_derivative() -> None:
    dt = 0.002
    t = np.arange(0.0, 4.0, dt)
    f = np.array([0.7, 1.9, 3.1])
    omega = np.sin(2 * np.pi * np.outer(t, f))
    omega_dot = 2 * np.pi * f * np.cos(2 * np.pi * np.outer(t, f))
    settings = SmootherSettings(window=0.3)
    w = settings.samples(dt)
    measured = convolve_columns(omega, savgol_kernel(w, 3, 1, dt))[w:-w]
    model = convolve_columns(omega_dot, rate_kernel(settings, dt))[w:-w]
    # The whole-sample step response is off by half a sample: a phase error of π f dt.
    shifted = convolve_columns(omega_dot, np.cumsum(savgol_kernel(w, 3, 1, dt))[:-1] * dt
                               if w % 2 == 0 else np.concatenate(
                                   [np.cumsum(savgol_kernel(w, 3, 1, dt))[:-1] * dt, [0.0]]))
    error = np.max(np.abs(measured - model), axis=0) / np.max(np.abs(measured), axis=0)
    naive = np.max(np.abs(measured - shifted[w:-w]), axis=0) / np.max(np.abs(measured), axis=0)
    assert np.all(error < 1e-3), error
    assert np.all(naive > 10 * error), naive


@pytest.fixture(scope="module")
def imu_flight(tmp_path_factory: pytest.TempPathFactory) -> tuple[FlightData, VehicleConfig,
                                                                   dict]:
    config = load_vehicle("quad_x")
    directory = tmp_path_factory.mktemp("imu-flight")
    Simulator(config, settings=SimulationSettings(seed=3, log_rate=250.0)).run(
        excitation_trajectory(ExcitationSpec(duration=20.0)), directory)
    return (load_flight(directory / "pose.csv", config), config,
            read_meta(Path(directory) / "meta.json")["truth"])


def _balance(flight: FlightData, config: VehicleConfig):
    prior = with_imu_quantities(config.with_parameters(config.theta * PRIOR_FACTORS), flight)
    result = fit_wrench_balance(flight, prior, prior_from_config(prior, EstimatorSettings()))
    sigma = np.sqrt(np.sum(result.sigma_parts**2, axis=0))
    return result, sigma


def test_the_gyro_answers_the_yaw_channel_the_twice_differentiated_pose_cannot(
        imu_flight: tuple[FlightData, VehicleConfig, dict]) -> None:
    flight, config, _ = imu_flight
    assert imu_segments(flight, 2.0)
    with_imu, sigma_imu = _balance(flight, config)
    pose_only, sigma_pose = _balance(replace(flight, imu=None), config)
    truth = config.theta
    yaw = [0, 2, 5]  # c_T, c_M, j_z
    for result, sigma in ((with_imu, sigma_imu), (pose_only, sigma_pose)):
        det = [j for j in yaw if result.determined[j]]
        assert np.all(np.abs(result.data.value[det] - truth[det]) < 3 * sigma[det])
    assert with_imu.determined[yaw].all()
    # c_M and j_z: the gyro's derivative is far less noisy than the attitude's second.
    assert sigma_imu[2] < 0.5 * sigma_pose[2]
    assert sigma_imu[5] < 0.5 * sigma_pose[5]


def test_an_autopilot_pose_takes_the_force_from_the_accelerometer_and_its_biases(
        imu_flight: tuple[FlightData, VehicleConfig, dict]) -> None:
    flight, config, truth = imu_flight
    result, sigma = _balance(replace(flight, pose_source="autopilot"), config)
    names = list(result.estimate.names)
    bias = np.array(truth["imu"]["accel_bias_m_s2"])
    at = [names.index(f"accel_bias_{a}") for a in "xyz"]
    determined = result.determined[at]
    assert determined.any()
    assert np.all(np.abs(result.data.value[at] - bias)[determined] < 3 * sigma[at][determined])
    assert result.determined[0]
    assert abs(result.data.value[0] - config.theta[0]) < 3 * sigma[0]
