"""Tests of the diagnosis workflow: the residual, the candidates, and hidden-effect flights.

Each hidden-effect test flies the simulator with one catalogue effect hidden at the
magnitude of `tests.support.hidden` (one seed) and checks the acceptance: the effect is
named first, its 95 % CI contains the truth, the held-out residual RMS on the flagged
axes shrinks by at least 50 %, and θ re-fitted with the effect is closer to the truth than
without.
"""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.discrepancy.candidates import candidate_library, effect_columns
from mavsysid.discrepancy.diagnosis import DiagnosisSettings, diagnose_flight
from mavsysid.discrepancy.residuals import (
    ResidualProblem,
    SmootherSettings,
    acceleration_kernel,
    smooth_pose,
)
from mavsysid.estimation.flight import FlightData
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.model_effects import effect_from_values
from mavsysid.vehicle.rotation import quat_exp
from scipy.signal import savgol_filter

from mavsysid.errors import InputError, JobFailedError
from tests.support.hidden import ground_trajectory, hidden_flight

#: The hidden magnitudes (`tests.support.hidden`; bench/diagnose_accuracy.py uses the same).
CASES = {
    "motor_lag": {"tau": 0.04},
    "pose_delay": {"delay": 0.02},
    "body_drag": {"k": 0.05 * 1.56779 * 9.81 / 9.0},  # 5 % of the weight at 3 m/s
    "rotor_drag_linear": {"k": 3e-4},  # ≈ 3.5× the quadratic one in hover (see bench)
    "marker_offset": {"x": 0.02, "y": -0.02, "z": 0.01},  # 3 cm
    "cog_offset": {"x": 0.006, "y": -0.005, "z": 0.006},  # 1 cm
    "wind": {"x": 1.6, "y": 1.2},  # 2 m/s
    "thrust_drift": {"rate": -0.08 / 30.0},  # −8 % over the 30 s flight
    "ground_effect": {"rotor_radius": 0.1},
    "rotor_inertia": {"J_r": 1.7e-5},  # RotorS's Firefly rotor: 5 g at 0.1 m radius
    "rotor_speed_lag": {"tau": 0.02},  # a speed sensor that averages over ~20 ms
}
PAIRS = (("motor_lag", "body_drag"), ("marker_offset", "wind"), ("thrust_drift", "cog_offset"))


@pytest.fixture(scope="module")
def config():
    return load_vehicle("firefly")


@pytest.fixture(scope="module")
def flights(tmp_path_factory: pytest.TempPathFactory, config):
    """Hidden-effect flights by key, simulated once per module on first use."""
    root = tmp_path_factory.mktemp("diagnosis")
    cache: dict[tuple, FlightData] = {}

    def get(names: tuple[str, ...], seed: int = 0) -> FlightData:
        key = (names, seed)
        if key not in cache:
            effects = [effect_from_values(n, CASES[n]) for n in names]
            trajectory = ground_trajectory() if "ground_effect" in names else None
            cache[key] = hidden_flight(config, root / f"{'+'.join(names) or 'clean'}-{seed}",
                                       effects, seed=seed, trajectory=trajectory)
        return cache[key]

    return get


def _start_theta(config, seed: int) -> np.ndarray:
    """θ 10 % off the truth (seeded): what an estimate with the effect unmodelled gives."""
    return config.theta * (1.0 + np.random.default_rng(500 + seed).uniform(-0.1, 0.1, 6))


def _theta_error(theta: np.ndarray, truth: np.ndarray) -> float:
    return float(np.mean(np.abs(theta / truth - 1.0)))


# --- the residual -------------------------------------------------------------------


def test_smoother_recovers_accelerations_of_a_known_motion():
    """A circle with a constant yaw rate: a within 0.5 % (the smoother's attenuation at
    1.2 rad/s with a 0.3 s window is 0.25 %), ω exact and ω̇ = 0."""
    dt, w, rad = 0.01, 1.2, 1.0
    t = np.arange(0.0, 10.0, dt)
    p = np.column_stack([rad * np.cos(w * t), rad * np.sin(w * t), 1.0 + 0 * t])
    yaw_rate = 0.5
    q = quat_exp(np.column_stack([0 * t, 0 * t, yaw_rate * t]))
    pose = smooth_pose(t, p, q, SmootherSettings(window=0.3))
    inner = slice(50, -50)
    a = -w**2 * p[:, :2]
    np.testing.assert_allclose(pose.acceleration[inner, :2], a[inner], atol=5e-3 * w**2 * rad)
    np.testing.assert_allclose(pose.rates[inner, 2], yaw_rate, atol=1e-6)
    np.testing.assert_allclose(pose.angular_acceleration[inner], 0.0, atol=1e-6)


def test_acceleration_kernel_is_what_the_smoother_does_to_accelerations():
    """SG second derivative of p equals the kernel applied to p̈ (up to O(dt²))."""
    dt = 0.01
    t = np.arange(0.0, 10.0, dt)
    p = np.sin(3 * t) + 0.3 * np.sin(7.1 * t)
    a = -9 * np.sin(3 * t) - 0.3 * 7.1**2 * np.sin(7.1 * t)
    settings = SmootherSettings(window=0.25)
    w = settings.samples(dt)
    direct = savgol_filter(p, w, settings.polyorder, deriv=2, delta=dt)
    kernel = acceleration_kernel(settings, dt)
    assert kernel.sum() == pytest.approx(1.0)
    via = np.convolve(a, kernel, mode="same")
    inner = slice(w, -w)
    assert np.max(np.abs(direct - via)[inner]) < 0.01 * np.max(np.abs(a))
    assert np.max(np.abs(direct - savgol_filter(a, w, settings.polyorder))[inner]) > 0.1


def test_clean_flight_residual_is_at_the_noise_floor(config, flights):
    """No effect: the replayed model matches the measurement to the smoothed noise level."""
    flight = flights((), 0)
    problem = ResidualProblem(flight, config, config.theta, SmootherSettings(window=0.6))
    r = problem.residual()[problem.keep()]
    rms = np.sqrt(np.mean(r**2, axis=0))
    assert np.all(rms[:3] < 0.01)   # m/s²
    assert np.all(rms[3:] < 0.03)   # rad/s²


def test_linear_candidate_columns_reproduce_the_effect(config, flights):
    """For an effect linear in its parameters, r(v) − r(0) = −A v."""
    flight = flights((), 0)
    problem = ResidualProblem(flight, config, config.theta, SmootherSettings(window=0.6))
    r0 = problem.residual()
    for cand in candidate_library(["body_drag", "wind", "marker_offset", "thrust_drift"]):
        A = effect_columns(problem, cand, [], r0)
        v = np.array([3.0 * p.scale for p in cand.effect.parameters])
        effect = cand.effect(**dict(zip(cand.effect.parameter_names(), v, strict=True)))
        change = problem.residual([effect]) - r0
        np.testing.assert_allclose(change, -A @ v, atol=1e-6 * np.abs(change).max() + 1e-12)


# --- hidden effects -----------------------------------------------------------------


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.slow
def test_hidden_effect_is_named_fitted_and_closes_the_gap(config, flights, name):
    """Named first, 95 % CI holds the truth, held-out gap shrinks ≥ 50 %, θ moves closer."""
    flight = flights((name,), 0)
    d = diagnose_flight(flight, config, _start_theta(config, 0), with_nis=False)
    named = [f.effect.name for f in d.effects]
    assert named and named[0] == name, f"named {named}, ties {d.ties}"
    first = d.effects[0]
    truth = np.array([CASES[name].get(p, 0.0) for p in first.effect.parameter_names()])
    inside = (first.ci95[:, 0] <= truth) & (truth <= first.ci95[:, 1])
    assert np.all(inside), f"{first.effect} CI {first.ci95.tolist()} misses {truth}"
    assert d.gap.shrink >= 0.5, f"held-out shrink {d.gap.shrink:.2f}"
    assert np.all(d.gap.after.rms <= d.gap.before.rms * 1.05)
    assert _theta_error(d.theta_after, config.theta) < _theta_error(d.theta_before, config.theta)


@pytest.mark.parametrize("pair", PAIRS, ids=["+".join(p) for p in PAIRS])
@pytest.mark.slow
def test_two_hidden_effects_are_both_named(config, flights, pair):
    """Two effects hidden at once are both named."""
    flight = flights(pair, 0)
    d = diagnose_flight(flight, config, _start_theta(config, 1), with_nis=False)
    named = {f.effect.name for f in d.effects}
    assert set(pair) <= named, f"named {named}"


@pytest.mark.parametrize("seed", [10, 11, 12])
def test_no_effect_no_discrepancy(config, flights, seed):
    """With nothing hidden the diagnosis names nothing."""
    flight = flights((), seed)
    d = diagnose_flight(flight, config, _start_theta(config, seed), with_nis=False)
    assert d.effects == ()
    assert d.gap.shrink == 0.0


def test_known_effect_is_not_a_candidate_and_explains_the_flight(config, flights):
    """With the hidden motor lag given as known, nothing is left to find."""
    flight = flights(("motor_lag",), 0)
    known = [effect_from_values("motor_lag", CASES["motor_lag"])]
    d = diagnose_flight(flight, config, _start_theta(config, 0), known_effects=known,
                        with_nis=False)
    assert d.effects == ()
    assert [e.name for e in d.augmented_effects] == ["motor_lag"]


@pytest.mark.slow
def test_nis_before_and_after_for_a_pose_channel_effect(config, flights):
    """The EKF's NIS is too large with a hidden pose delay and consistent once it is named."""
    flight = flights(("pose_delay",), 0)
    d = diagnose_flight(flight, config, _start_theta(config, 0))
    assert d.gap.before.nis_mean is not None and d.gap.after.nis_mean is not None
    assert d.gap.after.nis_mean < d.gap.before.nis_mean


# --- bad input ----------------------------------------------------------------------


def test_short_flight_is_refused(config, flights):
    """A flight too short to hold out 30 % is refused with one line."""
    flight = flights((), 0).time_slice(0.0, 4.0)
    with pytest.raises(InputError, match="too short"):
        diagnose_flight(flight, config, with_nis=False)


def test_wrong_rotor_count_and_bad_theta_are_refused(config, flights):
    """A log for another rotor count, or an unphysical θ, is refused with one line."""
    flight = flights((), 0)
    quad = load_vehicle("quad_x")
    with pytest.raises(InputError, match="rotor"):
        diagnose_flight(flight, quad, with_nis=False)
    with pytest.raises(InputError, match="θ"):
        diagnose_flight(flight, config, np.array([1e-5, 0.01, 1e-7, -1.0, 0.04, 0.1]),
                        with_nis=False)
    with pytest.raises(InputError, match="held-out"):
        diagnose_flight(flight, config, settings=DiagnosisSettings(holdout=0.9))


def test_non_uniform_sampling_is_resampled_not_refused(config, flights):
    """A log whose clock jumps 4 ms is put on a uniform grid, and says so; with
    nothing hidden, nothing is named (the refusal without resampling: test_resample.py)."""
    flight = flights((), 0)
    t = flight.t.copy()
    t[100:] += 0.004
    jumpy = FlightData(t, flight.position, flight.quaternion, flight.rotor_speeds, "x.csv")
    d = diagnose_flight(jumpy, config, _start_theta(config, 0), with_nis=False)
    assert any(note.startswith("pose log resampled") for note in d.notes)
    assert d.effects == ()


@pytest.mark.slow
def test_results_are_reproducible(config, flights):
    """The same flight gives the same diagnosis."""
    flight = flights(("body_drag",), 0)
    a = diagnose_flight(flight, config, _start_theta(config, 0), with_nis=False)
    b = diagnose_flight(flight, config, _start_theta(config, 0), with_nis=False)
    assert [f.effect for f in a.effects] == [f.effect for f in b.effects]
    np.testing.assert_array_equal(a.theta_after, b.theta_after)


def test_motor_lag_filter_matches_its_recursion():
    """The catalogue's IIR fast path (uniform steps) equals the first-order-hold recursion."""
    from mavsysid.vehicle.model_effects import MotorLag

    t = np.arange(0.0, 5.0, 0.01)
    x = np.random.default_rng(0).normal(500.0, 30.0, (t.size, 6))
    tau = 0.04
    a = np.exp(-0.01 / tau)
    b = 1.0 - tau / 0.01 * (1.0 - a)
    ref = np.empty_like(x)
    ref[0] = x[0]
    for i in range(1, t.size):
        ref[i] = a * ref[i - 1] + (1.0 - a) * x[i - 1] + b * (x[i] - x[i - 1])
    np.testing.assert_allclose(MotorLag(tau=tau).acting_rotor_speeds(t, x), ref, rtol=1e-12)


def test_a_filter_that_cannot_follow_the_log_refuses_the_diagnosis(config, flights, monkeypatch):
    """A diverged EKF refuses the diagnosis (exit 3) instead of reporting no discrepancy."""
    import mavsysid.estimation as estimation

    def diverges(*args, **kwargs):
        raise JobFailedError("x.csv: the parameter filter diverged")

    monkeypatch.setattr(estimation, "estimate_with_effects", diverges)
    with pytest.raises(JobFailedError, match=r"x\.csv: the parameter filter diverged"):
        diagnose_flight(flights((), 0), config, _start_theta(config, 0), with_nis=True)
