"""Tests of the realistic sensor path: the on-board estimator's pose and the logger's timing."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.log_timing import LogTiming, degrade_pose_log
from mavsysid.flight.offline.sensor_path import OnboardPoseEstimate
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.rotation import quat_exp, quat_log, quat_multiply
from mavsysid.vehicle.trajectory import PiecewisePolynomial

_DT = 0.002  # s, 500 Hz


def _feed(effect: OnboardPoseEstimate, t: np.ndarray, p: np.ndarray, q: np.ndarray):
    effect.reset(0.001)
    out = [effect.measure_pose(float(ti), pi, qi) for ti, pi, qi in zip(t, p, q, strict=True)]
    return np.array([o[0] for o in out]), np.array([o[1] for o in out])


def test_ramp_lags_by_delay_plus_time_constant() -> None:
    """Without noise a ramp comes out late by the delay plus the low pass's τ."""
    delay, tau, speed, rate = 0.02, 0.015, 1.3, 0.7
    effect = OnboardPoseEstimate(delay=delay, time_constant=tau, position_sigma=0.0,
                                 attitude_sigma=0.0)
    t = np.arange(0.0, 2.0, _DT)
    p = np.column_stack([speed * t, np.zeros_like(t), np.ones_like(t)])
    q = quat_exp(np.column_stack([np.zeros_like(t), np.zeros_like(t), rate * t]))
    p_out, q_out = _feed(effect, t, p, q)
    late = t > 0.5  # transients of the filter (e^(-0.5/τ)) long gone
    lag = t[late] - p_out[late, 0] / speed
    yaw = quat_log(q_out[late])[:, 2]
    # The discrete low pass of step Δt lags by Δt·a/(1 − a), a = e^(−Δt/τ): ≈ τ − Δt/2.
    a = np.exp(-_DT / tau)
    expected = delay + _DT * a / (1.0 - a)
    np.testing.assert_allclose(lag, expected, atol=1e-6)
    np.testing.assert_allclose(t[late] - yaw / rate, expected, atol=1e-6)


def test_noise_is_correlated_with_the_stationary_sigma() -> None:
    """Gauss–Markov noise: σ as configured, lag-1 correlation e^(−Δt/T_c), not white."""
    sigma, corr = 0.005, 0.1
    effect = OnboardPoseEstimate(delay=0.0, time_constant=0.0, position_sigma=sigma,
                                 attitude_sigma=2 * sigma, correlation_time=corr, seed=3)
    t = np.arange(0.0, 200.0, _DT)
    p = np.zeros((t.size, 3))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    p_out, q_out = _feed(effect, t, p, q)
    phi = quat_log(q_out)
    # 200 s hold 2000 correlation times: σ within a few %.
    np.testing.assert_allclose(p_out.std(axis=0), sigma, rtol=0.1)
    np.testing.assert_allclose(phi.std(axis=0), 2 * sigma, rtol=0.1)
    rho = np.corrcoef(p_out[:-1, 0], p_out[1:, 0])[0, 1]
    assert rho == pytest.approx(np.exp(-_DT / corr), abs=0.01)
    assert np.all(np.abs(np.linalg.norm(q_out, axis=1) - 1.0) < 1e-12)


def test_same_seed_same_noise_and_reset_restarts() -> None:
    t = np.arange(0.0, 0.5, _DT)
    p = np.zeros((t.size, 3))
    q = quat_multiply(np.tile([1.0, 0, 0, 0], (t.size, 1)), quat_exp(np.zeros((t.size, 3))))
    a, b = OnboardPoseEstimate(seed=1), OnboardPoseEstimate(seed=1)
    first = _feed(a, t, p, q)[0]
    np.testing.assert_array_equal(first, _feed(b, t, p, q)[0])
    np.testing.assert_array_equal(first, _feed(a, t, p, q)[0])
    assert not np.array_equal(first, _feed(OnboardPoseEstimate(seed=2), t, p, q)[0])


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError):
        OnboardPoseEstimate(correlation_time=0.0)
    with pytest.raises(ValueError):
        OnboardPoseEstimate(delay=-0.01)


def test_log_timing_jitter_drops_and_gaps() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 60.0, _DT)
    timing = LogTiming(jitter=3e-4, drop_probability=0.05, gaps=2, gap_duration=(0.1, 0.1))
    keep = timing.kept_rows(t, rng)
    assert keep[0] and keep[-1]
    # 5 % single drops and 2 × 0.1 s bursts (50 samples each, overlapping at most).
    lost = t.size - keep.sum()
    assert 0.05 * t.size + 50 - 4 * np.sqrt(t.size) < lost < 0.05 * t.size + 100 + 4 * np.sqrt(
        t.size)
    stamps = timing.stamps(t, rng)
    error = stamps - t
    assert np.all(np.abs(error) <= 0.4 * _DT + 1e-12)
    assert error.std() == pytest.approx(3e-4, rel=0.1)
    assert np.all(np.diff(stamps) > 0.0)
    coarse = LogTiming(jitter=5e-4, resolution=1e-3).stamps(t, rng)
    assert np.allclose(coarse / 1e-3, np.round(coarse / 1e-3))
    assert np.any(np.diff(coarse) == 0.0)  # a coarse clock repeats stamps


def _hover(duration: float) -> PiecewisePolynomial:
    knot = np.zeros((2, 5, 3))
    knot[:, 0] = (0.0, 0.0, 1.0)
    return PiecewisePolynomial.from_waypoints(np.array([0.0, duration]), knot, np.zeros((2, 3)))


def test_simulated_flight_through_the_sensor_path(tmp_path) -> None:
    """A hover logged through the on-board pose and a lossy logger reads back as a pose log."""
    config = load_vehicle("micro_quad")
    sigma = 10 * config.noise.position_sigma
    effect = OnboardPoseEstimate(position_sigma=sigma, attitude_sigma=0.01,
                                 correlation_time=0.05, seed=5)
    settings = SimulationSettings(log_rate=500.0, seed=5, sensor_noise=False)
    Simulator(config, settings=settings, effects=[effect]).run(_hover(4.0), tmp_path / "f")
    truth = read_pose_log(tmp_path / "f" / "truth.csv")
    before = read_pose_log(tmp_path / "f" / "pose.csv")
    # At hover the lag does not matter: what is left is the correlated noise.
    error = before.position - truth.position
    assert error.std(axis=0) == pytest.approx(np.full(3, sigma), rel=0.35)
    kept = degrade_pose_log(tmp_path / "f", LogTiming(seed=5, gaps=1))
    after = read_pose_log(tmp_path / "f" / "pose.csv", config.rotor_count)
    assert len(after) == kept < len(before)
    meta = read_meta(tmp_path / "f" / "meta.json")
    assert meta["log_timing"]["rows_kept"] == kept
    assert [e["name"] for e in meta["truth"]["effects"]] == ["onboard_pose"]
    # The values are the samples' own: each kept row is a row of the original log.
    rows = np.searchsorted(before.t, after.t - 0.001)
    rows = np.where(np.abs(before.t[np.minimum(rows + 1, len(before) - 1)] - after.t)
                    < np.abs(before.t[rows] - after.t), rows + 1, rows)
    np.testing.assert_allclose(after.position, before.position[rows], atol=2e-6)
