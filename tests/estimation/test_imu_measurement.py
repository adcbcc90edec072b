"""The parameter EKF reads the IMU: its readings per step, the update, what it buys."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation.answer import with_imu_quantities
from mavsysid.estimation.filter.ekf import FilterRun, ParameterEKF
from mavsysid.estimation.filter.estimator import EstimatorSettings, flight_initial_state_sigma
from mavsysid.estimation.filter.imu_measurement import (
    LOWPASS_BANDWIDTH,
    imu_steps,
    lowpass_delay,
)
from mavsysid.estimation.filter.likelihood import scaled_noise
from mavsysid.estimation.flight import FlightData, Imu, ImuSeries
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import prior_from_config
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

#: The pose of these flights is 10× noisier than the built-in motion capture's (5 mm, 1°):
#: a pose that leaves room for the IMU to add to it.
POSE_NOISE = 10.0
#: Process-noise scale the filters run at (the simulated flight has none).
NOISE_SCALE = 0.1


def _vehicle() -> VehicleConfig:
    cfg = load_vehicle("quad_x")
    nz = cfg.noise
    return replace(cfg, noise=replace(nz, position_sigma=nz.position_sigma * POSE_NOISE,
                                      attitude_sigma=nz.attitude_sigma * POSE_NOISE))


@pytest.fixture(scope="module")
def imu_flight(tmp_path_factory) -> tuple[FlightData, np.ndarray]:
    """An 8 s excitation flight at 250 Hz with a noisy, biased IMU; and the truth of θ, the
    gyro's and the accelerometer's biases and the IMU's offset (15,)."""
    cfg = _vehicle()
    directory = tmp_path_factory.mktemp("imu") / "flight"
    Simulator(cfg, settings=SimulationSettings(seed=4, log_rate=250.0)).run(
        excitation_trajectory(ExcitationSpec(duration=8.0)), directory)
    imu = json.loads((directory / "meta.json").read_text())["truth"]["imu"]
    truth = np.concatenate([cfg.theta, imu["gyro_bias_rad_s"], imu["accel_bias_m_s2"],
                            imu["position_m"]])
    return load_flight(directory / "pose.csv", cfg), truth


def _run(flight: FlightData, with_bias_states: bool, read_imu: bool | None) -> FilterRun:
    """The filter from a prior 30 % off, at `NOISE_SCALE`."""
    cfg = scaled_noise(_vehicle(), NOISE_SCALE)
    cfg = cfg.with_parameters(cfg.theta * np.array([1.3, 0.7, 1.3, 0.7, 0.7, 0.7]))
    if with_bias_states:
        cfg = with_imu_quantities(cfg, flight, every_sensor=True)
    sigma = (cfg.noise.position_sigma, cfg.noise.attitude_sigma)
    ekf = ParameterEKF(cfg, prior_from_config(cfg, EstimatorSettings()), sigma,
                       read_imu=read_imu)
    return ekf.run(flight, flight_initial_state_sigma(flight, sigma))


def test_the_imu_update_recovers_theta_and_the_biases(imu_flight):
    """θ, both sensors' biases and the IMU's offset within 3 σ of the truth; the IMU's NIS
    near its 6 degrees of freedom."""
    flight, truth = imu_flight
    run = _run(flight, with_bias_states=True, read_imu=None)
    estimate = run.estimate
    assert estimate.names[6:] == ("gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x",
                                  "accel_bias_y", "accel_bias_z", "imu_x", "imu_y", "imu_z")
    z = (estimate.value - truth) / estimate.sigma
    assert np.all(np.abs(z) < 3.0), dict(zip(estimate.names, np.round(z, 2), strict=True))
    # The biases are determined far beyond their prior σ (0.005 rad/s, 0.1 m/s²).
    assert np.all(estimate.sigma[6:12] < 0.1 * np.repeat([0.005, 0.1], 3))
    assert run.history.imu_nis is not None
    assert 3.0 < np.nanmean(run.history.imu_nis) < 9.0


def test_the_imu_tightens_the_estimate(imu_flight):
    """σ of j_x, j_y, j_z and c_M at least 25 % tighter with the IMU, c_T's no looser (the
    accelerometer's z bias shares c_T's signature at near-constant thrust)."""
    flight, _ = imu_flight
    pose = _run(flight, with_bias_states=True, read_imu=False).estimate.sigma[:6]
    imu = _run(flight, with_bias_states=True, read_imu=None).estimate.sigma[:6]
    assert imu[0] <= 1.001 * pose[0]
    assert np.all(imu[2:] < 0.75 * pose[2:]), imu / pose


def test_without_bias_states_a_biased_imu_misleads(imu_flight):
    """The same IMU read with its biases taken as 0: θ lands many σ off the truth."""
    flight, truth = imu_flight
    estimate = _run(flight, with_bias_states=False, read_imu=True).estimate
    z = (estimate.value - truth[:6]) / estimate.sigma
    assert np.max(np.abs(z)) > 5.0


def test_a_flight_without_imu_runs_as_before(imu_flight):
    """Without the IMU (none logged, or not read) the filter is the pose's alone, to the bit,
    and its history has no IMU NIS."""
    flight, _ = imu_flight
    flight = flight.time_slice(0.0, 3.0)
    bare = _run(replace(flight, imu=None), with_bias_states=False, read_imu=None)
    unread = _run(flight, with_bias_states=False, read_imu=None)  # no bias states: not read
    np.testing.assert_array_equal(bare.estimate.covariance, unread.estimate.covariance)
    np.testing.assert_array_equal(bare.states, unread.states)
    assert bare.log_likelihood == unread.log_likelihood
    assert bare.history.imu_nis is None and unread.history.imu_nis is None


def test_step_by_step_equals_the_compiled_run(imu_flight):
    """predict(), update_imu() and update() per sample reach run()'s x and P."""
    flight, _ = imu_flight
    flight = flight.time_slice(0.0, 1.0)
    cfg = with_imu_quantities(_vehicle(), flight, every_sensor=True)
    sigma = (cfg.noise.position_sigma, cfg.noise.attitude_sigma)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    prior = prior_from_config(cfg, EstimatorSettings())
    a = ParameterEKF(cfg, prior, sigma)
    run = a.run(flight, state_sigma)
    steps, _, _ = a.imu_steps(flight)
    b = ParameterEKF(cfg, prior, sigma)
    t, q, n = flight.t, flight.quaternion, flight.rotor_speeds
    b.initialize(flight.position[0], q[0], run.states[0][3:6], run.states[0][10:13], state_sigma)
    for k in range(1, len(flight)):
        b.predict(n[k - 1], t[k] - t[k - 1], n[k])
        nis = b.update_imu(steps.z[k], steps.info[k, 2:8], tuple(steps.info[k, 0:2]),
                           steps.info[k, 8])
        assert nis == pytest.approx(run.history.imu_nis[k], rel=1e-6)
        b.update(np.concatenate([flight.position[k], q[k]]))
    np.testing.assert_allclose(b.x, a.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.P, a.P, rtol=1e-7, atol=1e-20)


def _series(t: np.ndarray, cutoff: float | None = None) -> ImuSeries:
    return ImuSeries(t, np.column_stack([t, 2.0 * t, np.ones_like(t)]), cutoff)


def test_a_faster_imu_is_averaged_over_each_step():
    """Five samples a step: their mean, the weight of the step's end, σ² / 5."""
    noise = load_vehicle("quad_x").noise
    t = np.arange(101) * 0.01
    ts = np.arange(1, 500) * 0.002 - 1e-9
    steps = imu_steps(t, Imu(_series(ts), _series(ts)), noise)
    k = 40  # (0.39, 0.40]: samples at 0.392 … 0.400
    np.testing.assert_allclose(steps.z[k], [0.396, 0.792, 1.0] * 2, atol=1e-8)
    np.testing.assert_allclose(steps.info[k, 0:2], 0.6, atol=1e-6)
    np.testing.assert_allclose(steps.info[k, 2:8], np.repeat([noise.gyro_sigma**2,
                                                              noise.accel_sigma**2], 3) / 5)
    np.testing.assert_allclose(steps.info[k, 8], 0.01)
    assert np.all(np.isnan(steps.z[0]))


def test_a_low_passed_imu_counts_its_bandwidth_and_delay():
    """An autopilot's 20 Hz low-pass: samples re-timed by its delay, and worth 2 B dt each."""
    noise = load_vehicle("quad_x").noise
    t = np.arange(101) * 0.01
    ts = np.arange(1, 400) * 0.0025 + 1e-6
    steps = imu_steps(t, Imu(_series(ts, 20.0), None), noise)
    delay = lowpass_delay(20.0)
    assert delay == pytest.approx(np.sqrt(2.0) / (2 * np.pi * 20.0))
    k = 50
    inside = ts[(ts - delay > t[k - 1]) & (ts - delay <= t[k])]
    np.testing.assert_allclose(steps.z[k, 0], inside.mean())
    n_eff = inside.size * 2.0 * LOWPASS_BANDWIDTH * 20.0 * 0.0025
    assert n_eff < inside.size / 4
    np.testing.assert_allclose(steps.info[k, 2], noise.gyro_sigma**2 / n_eff, rtol=1e-6)
    assert np.all(np.isnan(steps.z[:, 3:]))


def test_a_slower_imu_uses_each_sample_once():
    """A 40 Hz IMU under a 100 Hz pose: each sample in one step, the others without."""
    t = np.arange(101) * 0.01
    ts = 0.004 + np.arange(40) * 0.025
    steps = imu_steps(t, Imu(_series(ts), None), load_vehicle("quad_x").noise)
    used = np.isfinite(steps.z[:, 0])
    assert used.sum() == ts.size
    np.testing.assert_allclose(steps.z[used, 0], ts)
    np.testing.assert_allclose(steps.info[used, 0], (ts - t[used.nonzero()[0] - 1]) / 0.01)
    np.testing.assert_allclose(steps.info[used, 2], load_vehicle("quad_x").noise.gyro_sigma**2)


def test_empty_imu_reads_nothing():
    """No IMU: every step without a reading."""
    steps = imu_steps(np.arange(5.0), None, load_vehicle("quad_x").noise)
    assert steps.steps == 0 and steps.z.shape == (5, 6)

