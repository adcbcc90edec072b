"""Tests of putting non-uniformly sampled logs on a uniform grid for the diagnosis.

The acceptance test flies the simulator with a hidden motor lag and logs the pose the way
an autopilot or a motion-capture system on a busy computer does: 20 % jitter of the
sample times and dropped samples (single, bursts, and one gap too long to bridge).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.discrepancy.diagnosis import diagnose_flight
from mavsysid.discrepancy.resample import (
    INTERPOLATION_SUPPORT,
    MAX_INTERPOLATED,
    average_blocks,
    resample_flight,
)
from mavsysid.discrepancy.residuals import ResidualProblem, SmootherSettings
from mavsysid.estimation.flight import FlightData, Imu, ImuSeries
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import effect_from_values
from mavsysid.vehicle.rotation import quat_exp, quat_log, quat_multiply

from mavsysid.errors import InputError

TAU = 0.04  # s, the hidden motor lag (as in `tests.support.hidden`)


def _motion(t: np.ndarray) -> FlightData:
    """A smooth known motion: position and attitude as functions of t, two rotors."""
    p = np.column_stack([np.sin(1.3 * t), 0.5 * np.cos(0.7 * t), 1.0 + 0.1 * t])
    rotvec = np.column_stack([0.2 * np.sin(t), 0.1 * np.cos(2 * t), 0.4 * t])
    n = np.column_stack([500.0 + 10.0 * t, 600.0 - 5.0 * t])
    return FlightData(t, p, quat_exp(rotvec), n, "motion.csv")


def _jittered_times(rng: np.random.Generator, duration: float, dt: float,
                    jitter: float) -> np.ndarray:
    return np.arange(0.0, duration, dt) + rng.uniform(-jitter, jitter,
                                                      int(np.ceil(duration / dt))) * dt


def test_uniform_log_is_used_as_it_is():
    """Within 5 % jitter nothing is interpolated: same object, correlation length = window."""
    t = 0.01 * np.arange(1000) + np.random.default_rng(1).uniform(-2e-4, 2e-4, 1000)
    flight = _motion(t)
    same, resampling = resample_flight(flight)
    assert same is flight and not resampling.resampled and resampling.valid.all()
    problem = ResidualProblem(same, load_vehicle("quad_x"), np.ones(6), SmootherSettings(),
                              resampling=resampling)
    assert problem.block == problem.window_samples


def test_jittered_log_is_interpolated_onto_the_median_grid():
    """20 % jitter: the grid holds the motion to far below motion-capture noise."""
    rng = np.random.default_rng(2)
    t = _jittered_times(rng, 10.0, 0.01, 0.2)
    uniform, resampling = resample_flight(_motion(t))
    assert resampling.resampled and resampling.valid.all() and resampling.gaps == ()
    assert resampling.dt == pytest.approx(float(np.median(np.diff(t))))
    np.testing.assert_allclose(np.diff(uniform.t), resampling.dt, rtol=1e-9)
    truth = _motion(uniform.t)
    assert np.max(np.abs(uniform.position - truth.position)) < 1e-6  # m (noise: 5e-4)
    angle = np.linalg.norm(quat_log(quat_multiply(
        uniform.quaternion * np.array([1, -1, -1, -1]), truth.quaternion)), axis=1)
    assert np.max(angle) < 5e-5  # rad (noise: 1.7e-3)
    np.testing.assert_allclose(uniform.rotor_speeds, truth.rotor_speeds, rtol=1e-9)
    assert resampling.block(61) == 61 + INTERPOLATION_SUPPORT - 1


def test_the_grid_keeps_what_it_does_not_resample():
    """The IMU at its own rate, the logged rotor-speed samples, the rotor scale's σ and the
    reader's notes come through resampling and averaging unchanged."""
    rng = np.random.default_rng(3)
    t = np.sort(_jittered_times(rng, 10.0, 0.002, 0.2))
    flight = _motion(t)
    gyro = ImuSeries(np.arange(0.0, 10.0, 0.001), np.zeros((10000, 3)), 0.0, "gyro")
    logged = replace(flight, imu=Imu(gyro, None), rotor_scale_sigma=0.04,
                     warnings=("3 NaN rows dropped",), segment_starts=(0, 2000))
    resampled, resampling = resample_flight(logged)
    averaged, _ = average_blocks(resampled, resampling)
    for grid in (resampled, averaged):
        assert grid.imu is logged.imu and grid.rotor_scale_sigma == 0.04
        assert grid.warnings == logged.warnings and grid.segment_starts == (0,)
    assert len(averaged) < len(resampled)


def test_long_gaps_and_reader_segments_are_not_bridged():
    """A gap longer than a few samples, and a reader's segment boundary, are left out of
    the residual with one smoother edge on each side; short dropouts are interpolated."""
    t = np.arange(0.0, 20.0, 0.01)
    keep = np.ones(t.size, bool)
    keep[300:302] = False   # two dropped samples: interpolated
    keep[800:850] = False   # 0.5 s: a gap
    t = t[keep]
    flight = _motion(t)
    boundary = int(np.searchsorted(t, 15.0))
    split = FlightData(flight.t, flight.position, flight.quaternion, flight.rotor_speeds,
                       flight.source, segment_starts=(0, boundary))
    uniform, resampling = resample_flight(split)
    assert [round(a, 2) for a, _ in resampling.gaps] == [7.99, t[boundary - 1].round(2)]
    assert resampling.gaps[0][1] - resampling.gaps[0][0] > MAX_INTERPOLATED * 0.01
    g = uniform.t
    assert not resampling.valid[(g > 8.0) & (g < 8.5)].any()
    assert resampling.valid[(g > 2.95) & (g < 3.05)].all()
    usable = resampling.usable(60)
    assert not usable[(g > 7.4) & (g < 9.1)].any() and usable[(g > 6.5) & (g < 7.3)].all()
    config = load_vehicle("quad_x")
    rotors = np.repeat(uniform.rotor_speeds, 2, axis=1)
    quad = FlightData(uniform.t, uniform.position, uniform.quaternion, rotors, "x.csv")
    problem = ResidualProblem(quad, config, config.theta, resampling=resampling)
    assert not problem.keep()[(g > 7.4) & (g < 9.1)].any()


def test_a_jittered_log_without_resampling_is_refused_naming_the_file():
    """The smoother itself still needs uniform samples, and says which file has none."""
    t = 0.01 * np.arange(2000.0)
    t[100:] += 0.004
    flight = _motion(t)
    quad = FlightData(t, flight.position, flight.quaternion,
                      np.repeat(flight.rotor_speeds, 2, axis=1), "logs/jittery.csv")
    config = load_vehicle("quad_x")
    with pytest.raises(InputError, match=r"^logs/jittery\.csv: .*uniform"):
        ResidualProblem(quad, config, config.theta)


def _jittered_lag_flight(directory: Path, seed: int) -> FlightData:
    """A hidden motor lag, the pose logged at a nominal 100 Hz with 20 % jitter and drops.

    The simulator logs at 500 Hz (every control tick); the log keeps, for each nominal
    10 ms sample, the one 2 ms early, on time or late (±20 % of the interval), then drops
    5 % of them singly, ten bursts of 2–3, and 0.4 s at once (a gap).
    """
    config = load_vehicle("firefly")
    Simulator(config, settings=SimulationSettings(seed=seed, log_rate=500.0),
              effects=[hidden_effect(effect_from_values("motor_lag", {"tau": TAU}))]
              ).run(excitation_trajectory(ExcitationSpec(duration=30.0)), directory)
    log = read_pose_log(directory / "pose.csv", config.rotor_count)
    rng = np.random.default_rng(100 + seed)
    nominal = np.arange(1, (len(log.t) - 2) // 5) * 5
    picks = nominal + rng.integers(-1, 2, nominal.size)
    keep = rng.random(picks.size) > 0.05
    for start in rng.integers(0, picks.size - 3, 10):
        keep[start:start + rng.integers(2, 4)] = False
    gap = int(0.55 * picks.size)
    keep[gap:gap + 40] = False
    rows = picks[keep]
    truth = read_meta(directory / "meta.json")["truth"]
    return FlightData(log.t[rows], log.position[rows], log.quaternion[rows],
                      log.rotor_speeds[rows], str(directory / "pose.csv"), truth=truth)


@pytest.mark.slow
def test_hidden_motor_lag_is_named_on_a_jittered_log_with_dropouts(tmp_path):
    """20 % jitter and dropouts; motor lag named, τ's CI holds 40 ms."""
    config = load_vehicle("firefly")
    flight = _jittered_lag_flight(tmp_path / "lag", seed=3)
    intervals = np.diff(flight.t)
    assert np.max(np.abs(intervals - 0.01)) > 0.15 * 0.01   # really jittered
    assert np.max(intervals) > 0.3                          # and with a gap
    theta = config.theta * (1.0 + np.random.default_rng(7).uniform(-0.1, 0.1, 6))
    d = diagnose_flight(flight, config, theta, with_nis=False)
    named = [f.effect.name for f in d.effects]
    assert named and named[0] == "motor_lag", f"named {named}, ties {d.ties}"
    lo, hi = d.effects[0].ci95[0]
    assert lo <= TAU <= hi, f"τ CI [{lo:.4f}, {hi:.4f}] misses {TAU}"
    assert any("resampled" in note for note in d.notes)
    i = int(np.argmax(intervals))
    assert not d.used[(d.t > flight.t[i]) & (d.t < flight.t[i + 1])].any()
