"""Tests of the diagnosis on fast logs: block averaging, the regression's solve, the cache.

A 500 Hz log (a Crazyflie's rate) is averaged to `DIAGNOSIS_RATE` before the smoother;
the acceptance flies the simulator at 500 Hz with a hidden motor lag and checks that the
diagnosis names it as on the 100 Hz log, with the time-like CI of the log's own rate.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.discrepancy.diagnosis import diagnose_flight
from mavsysid.discrepancy.regression import Regression
from mavsysid.discrepancy.resample import DIAGNOSIS_RATE, average_blocks, resample_flight
from mavsysid.discrepancy.residuals import ResidualProblem, SmootherSettings
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.progress import stage_listener
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import MarkerOffset, effect_from_values
from mavsysid.vehicle.rotation import quat_exp


def _motion(t: np.ndarray) -> FlightData:
    p = np.column_stack([np.sin(1.3 * t), 0.5 * np.cos(0.7 * t), 1.0 + 0.1 * t])
    q = quat_exp(np.column_stack([0.2 * np.sin(t), 0.1 * np.cos(2 * t), 0.4 * t]))
    q[::3] *= -1.0  # a logger's sign flips: the same attitudes
    n = np.column_stack([500.0 + 10.0 * t, 600.0 - 5.0 * t])
    return FlightData(t, p, q, n, "motion.csv")


def test_fast_log_is_averaged_over_blocks_to_the_diagnosis_rate():
    """500 Hz → blocks of 5: means of t, p, n; the sign-continuous mean attitude; 100 Hz."""
    t = np.arange(5003) * 0.002
    flight, resampling = resample_flight(_motion(t))
    fast, averaged = average_blocks(flight, resampling)
    assert averaged.averaged == 5 and len(fast) == 1000
    assert averaged.dt == pytest.approx(1.0 / DIAGNOSIS_RATE)
    assert averaged.log_dt == pytest.approx(0.002) and averaged.valid.all()
    np.testing.assert_allclose(fast.t, t[:5000].reshape(-1, 5).mean(axis=1))
    np.testing.assert_allclose(fast.position, _motion(t).position[:5000].reshape(-1, 5, 3)
                               .mean(axis=1))
    # The attitude at the block's mean time, to the order of the motion within 8 ms.
    truth = _motion(fast.t).quaternion
    truth *= np.sign(np.sum(truth * fast.quaternion, axis=1))[:, None]
    np.testing.assert_allclose(fast.quaternion, truth, atol=1e-5)
    same, kept = average_blocks(*resample_flight(_motion(np.arange(2000) * 0.01)))
    assert kept.averaged == 1 and len(same) == 2000


def test_normal_equations_match_the_least_squares_solution():
    """The regression's fit (through XᵀX) equals lstsq's, collinear and rank-deficient."""
    rng = np.random.default_rng(4)
    X = rng.normal(size=(600 * 6, 5))
    X[:, 1] = X[:, 0] + 1e-4 * X[:, 1]           # nearly collinear (c_D and a linear drag)
    X[:, 4] = 0.0                                  # an effect with no sensitivity
    y = X @ np.array([1.0, -2.0, 0.5, 3.0, 0.0]) + rng.normal(size=X.shape[0])
    reg = Regression(np.arange(600), np.ones(6), 1)
    rss, beta, cov = reg.fit(y, X)
    reference = np.linalg.lstsq(X, y, rcond=None)[0]
    np.testing.assert_allclose(beta, reference, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(rss.sum(), np.sum((y - X @ reference) ** 2), rtol=1e-9)
    assert cov[4, 4] == 0.0 and np.all(np.diag(cov)[:4] > 0.0)


def test_smoothed_pose_cache_gives_the_fresh_residual():
    """Cached smoothing (shared by θ copies) reproduces a fresh problem's residual."""
    t = np.arange(3000) * 0.01
    config = load_vehicle("quad_x")
    flight = _motion(t)
    flight = FlightData(t, flight.position, flight.quaternion,
                        np.tile(flight.rotor_speeds, 2), "motion.csv")
    offset = MarkerOffset(x=0.01, y=-0.02, z=0.005)
    problem = ResidualProblem(flight, config, config.theta, SmootherSettings())
    first = problem.residual([offset])
    other = replace(problem, theta=config.theta * 1.1)
    assert other.smoothed is problem.smoothed and len(problem.smoothed) == 1
    np.testing.assert_array_equal(problem.residual([offset]), first)
    fresh = ResidualProblem(flight, config, config.theta * 1.1, SmootherSettings())
    np.testing.assert_array_equal(other.residual([offset]), fresh.residual([offset]))
    assert not np.array_equal(problem.residual([MarkerOffset(x=0.02)]), first)


def _lag_flight(directory: Path, log_rate: float) -> FlightData:
    config = load_vehicle("firefly")
    settings = SimulationSettings(seed=2, log_rate=log_rate)
    effects = [hidden_effect(effect_from_values("motor_lag", {"tau": 0.04}))]
    Simulator(config, settings=settings, effects=effects).run(
        excitation_trajectory(ExcitationSpec(duration=30.0)), directory)
    log = read_pose_log(directory / "pose.csv", config.rotor_count)
    return FlightData(log.t, log.position, log.quaternion, log.rotor_speeds,
                      str(directory / "pose.csv"))


@pytest.mark.slow
def test_500_hz_log_is_diagnosed_as_its_100_hz_twin(tmp_path):
    """Hidden motor lag at 500 Hz: averaged to 100 Hz, named, τ's CI holds 40 ms."""
    config = load_vehicle("firefly")
    theta = config.theta * (1.0 + np.random.default_rng(3).uniform(-0.1, 0.1, 6))
    messages: list[str] = []
    with stage_listener(messages.append):
        fast = diagnose_flight(_lag_flight(tmp_path / "fast", 500.0), config, theta,
                               with_nis=False)
    slow = diagnose_flight(_lag_flight(tmp_path / "slow", 100.0), config, theta,
                           with_nis=False)
    for d in (fast, slow):
        assert [f.effect.name for f in d.effects][:1] == ["motor_lag"]
        lo, hi = d.effects[0].ci95[0]
        assert lo <= 0.04 <= hi
    assert any("averaged over blocks of 5" in note for note in fast.notes)
    # The 500 Hz log stamps rotor speeds to 2 ms: its CI is not widened by the 10 ms grid.
    width = np.diff(fast.effects[0].ci95[0])[0]
    assert width < 1.96 * 2 * 0.01 / np.sqrt(12.0)
    assert any(m.startswith("step 1: motor_lag") for m in messages)
    np.testing.assert_allclose(fast.theta_after, slow.theta_after, rtol=0.01)
