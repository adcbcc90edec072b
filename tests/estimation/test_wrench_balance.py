"""θ from the force and torque balance of simulated flights: accuracy, honest σ, statuses."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation.balance.fit import fit_wrench_balance
from mavsysid.estimation.filter.estimator import EstimatorSettings
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import Z95, prior_from_config
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.sensor_path import OnboardPoseEstimate
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import RotorDragLinear

from mavsysid.errors import JobFailedError

CONFIG = load_vehicle("micro_quad")
#: A prior 30–50 % off the truth, both directions.
PRIOR = CONFIG.with_parameters(CONFIG.theta * np.array([1.4, 0.6, 1.5, 0.65, 1.35, 1.5]))


def _covered(result, truth: np.ndarray) -> np.ndarray:
    sigma = np.sqrt(np.sum(result.sigma_parts**2, axis=0))
    return np.abs(result.data.value - truth) <= Z95 * sigma


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 4])
def test_motion_capture_flight_determines_theta_within_its_interval(simulate_flight, seed):
    """Motion-capture pose: all six determined, within 3 %, the truth inside every 95 % interval.

    The held-out end of the flight is predicted far better than by the prior.
    """
    flight = simulate_flight(CONFIG, seed, duration=30.0, log_rate=500.0)
    result = fit_wrench_balance(flight, PRIOR)
    truth = np.asarray(flight.true_theta)
    assert result.determined.all(), result.status
    assert np.all(np.abs(result.estimate.value / truth - 1.0) < 0.03), result.estimate.value
    assert _covered(result, truth).all()
    assert result.holdout.force_ratio < 0.2 and result.holdout.torque_ratio < 0.5
    assert abs(result.choices.delay) < 0.005


@pytest.mark.slow
def test_onboard_estimator_pose_gives_no_confident_wrong_answer(simulate_flight):
    """Lagged, smoothed, correlated pose noise 10× motion capture: every determined θ covers
    the truth; c_T is determined within 1 %; the pose's lag is found as the offset."""
    effect = OnboardPoseEstimate(delay=0.02, time_constant=0.015, position_sigma=0.005,
                                 attitude_sigma=0.0175, correlation_time=0.2, seed=7)
    flight = simulate_flight(CONFIG, 5, duration=40.0, effects=[effect], log_rate=500.0)
    result = fit_wrench_balance(flight, PRIOR)
    truth = np.asarray(flight.true_theta)
    assert result.determined[0]
    assert abs(result.estimate.value[0] / truth[0] - 1.0) < 0.01
    assert _covered(result, truth)[result.determined].all(), result.status
    assert 0.015 <= result.choices.delay <= 0.06, result.choices.delay


@pytest.mark.slow
def test_hidden_linear_rotor_drag_is_not_taken_for_c_d(simulate_flight):
    """A linear rotor drag about 0.5 c_D's size in hover: c_D is within 15 % and covered,
    or "not determined" (never the +50 % sum); c_T stays within 0.1 %."""
    effect = hidden_effect(RotorDragLinear(k=2e-7, k_z=0.0))
    flight = simulate_flight(CONFIG, 3, duration=30.0, effects=[effect], log_rate=500.0)
    result = fit_wrench_balance(flight, PRIOR)
    truth = np.asarray(flight.true_theta)
    assert abs(result.estimate.value[0] / truth[0] - 1.0) < 1e-3
    if result.determined[1]:
        assert abs(result.estimate.value[1] / truth[1] - 1.0) < 0.15, result.estimate.value
    assert _covered(result, truth)[result.determined].all(), result.status


@pytest.mark.slow
def test_repeated_pose_rows_change_the_answer_by_less_than_its_sigma(simulate_flight):
    """Each pose held for a second row (a logger twice as fast as its source) agrees with the
    un-held log within twice the two σ in quadrature (half the pose samples are gone, so the
    noise differs, not the physics)."""
    flight = simulate_flight(CONFIG, 6, duration=30.0, log_rate=500.0)
    held = np.arange(len(flight)) // 2 * 2
    repeated = replace(flight, position=flight.position[held],
                       quaternion=flight.quaternion[held])
    a, b = (fit_wrench_balance(f, PRIOR) for f in (flight, repeated))
    both = a.determined & b.determined
    assert both[[0, 3, 4]].all()
    sigma = np.hypot(*(np.sqrt(np.sum(r.sigma_parts**2, axis=0)) for r in (a, b)))
    assert np.all(np.abs(a.data.value - b.data.value)[both] <= 2.0 * sigma[both])


def test_too_short_a_flight_is_a_one_line_refusal():
    """No stretch as long as min_segment: one line naming the log."""
    t = np.arange(500) * 0.002
    flight = FlightData(t, np.zeros((500, 3)), np.tile([1.0, 0, 0, 0], (500, 1)),
                        np.full((500, 4), 1900.0), "short.csv")
    with pytest.raises(JobFailedError, match=r"^short\.csv: no stretch of at least 2 s") as e:
        fit_wrench_balance(flight, CONFIG)
    assert "\n" not in str(e.value)


def test_not_determined_parameters_keep_the_prior():
    """A parameter reported not determined carries the prior's value and σ exactly."""
    rng = np.random.default_rng(0)
    n = 6000
    t = np.arange(n) * 0.002
    # Level hover with noisy rotor speeds: c_T from the balance, no attitude motion.
    hover = np.sqrt(CONFIG.mass * 9.81 / (4 * CONFIG.theta[0]))
    speeds = hover * (1.0 + 0.001 * rng.standard_normal((n, 4)))
    p = np.column_stack([np.zeros(n), np.zeros(n), 1.0 + 1e-4 * rng.standard_normal(n)])
    flight = FlightData(t, p, np.tile([1.0, 0, 0, 0], (n, 1)), speeds, "hover.csv")
    prior = prior_from_config(PRIOR, EstimatorSettings())
    result = fit_wrench_balance(flight, PRIOR, prior)
    assert result.determined[0] and not result.determined[3:].any()
    keep = ~result.determined
    assert np.array_equal(result.estimate.value[keep], prior.value[keep])
    assert np.allclose(result.estimate.sigma[keep], prior.sigma[keep])


@pytest.mark.parametrize("kind", ["noise", "still", "split"])
def test_garbage_flights_get_a_one_line_refusal_or_an_answer(kind):
    """Random poses and speeds, a pose that never changes, short segments: a one-line
    refusal (JobFailedError) or an answer (which may determine nothing, keeping the prior
    there), never another exception or a warning."""
    rng = np.random.default_rng(["noise", "still", "split"].index(kind))
    n = 3000
    t = np.arange(n) * 0.002
    if kind == "noise":
        p, q = rng.standard_normal((n, 3)), rng.standard_normal((n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        speeds = rng.uniform(0.0, 3000.0, (n, 4))
    else:
        p, q = np.zeros((n, 3)), np.tile([1.0, 0, 0, 0], (n, 1))
        speeds = np.full((n, 4), 1900.0)
    starts = (0, 1000, 2000) if kind == "split" else (0,)
    flight = FlightData(t, p, q, speeds, f"{kind}.csv", segment_starts=starts)
    try:
        result = fit_wrench_balance(flight, CONFIG)
    except JobFailedError as error:
        assert str(error).startswith(f"{kind}.csv: ") and "\n" not in str(error)
    else:
        keep = ~result.determined
        assert np.array_equal(result.estimate.value[keep], result.prior.value[keep])


def test_result_as_json_carries_status_parts_and_choices():
    """as_dict is JSON-serialisable and carries, per parameter, status and σ parts."""
    rng = np.random.default_rng(1)
    n = 6000
    t = np.arange(n) * 0.002
    hover = np.sqrt(CONFIG.mass * 9.81 / (4 * CONFIG.theta[0]))
    speeds = hover * (1.0 + 0.001 * rng.standard_normal((n, 4)))
    p = np.column_stack([np.zeros(n), np.zeros(n), 1.0 + 1e-4 * rng.standard_normal(n)])
    flight = FlightData(t, p, np.tile([1.0, 0, 0, 0], (n, 1)), speeds, "hover.csv")
    doc = fit_wrench_balance(flight, PRIOR).as_dict()
    text = json.dumps(doc)
    assert "NaN" not in text and "Infinity" not in text
    assert doc["parameters"]["c_T"]["status"] == "determined"
    assert doc["parameters"]["j_x"]["status"] == "not determined"
    assert set(doc["parameters"]["c_T"]["sigma_parts"]) >= {"newey_west", "flight_halves"}
    assert set(doc["choices"]) == {"window_s", "roll_pitch_band_hz", "yaw_band_hz",
                                   "force_lowpass_hz", "delay_s", "delay_sigma_s"}
