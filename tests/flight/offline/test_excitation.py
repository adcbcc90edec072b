"""Tests of the built-in excitation trajectory."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.vehicle.flatness import flat_to_state


@pytest.fixture(scope="module")
def samples():
    traj = excitation_trajectory()
    t = np.linspace(0.0, traj.duration, 6001)
    return traj, t, traj.flat_outputs(t)


def test_excitation_is_thirty_seconds_fast_and_yawing(samples):
    """The default figure lasts 30 s, reaches ≥ 2 m/s and swings yaw both ways."""
    traj, _, flat = samples
    assert traj.duration == pytest.approx(30.0)
    assert np.linalg.norm(flat.velocity, axis=1).max() >= 2.0
    assert flat.yaw.max() > 0.5
    assert flat.yaw.min() < -0.5


def test_excitation_starts_and_ends_at_rest(samples):
    """Velocity to snap and yaw rate/acceleration vanish at both ends (hover to hover)."""
    traj, _, _ = samples
    ends = traj.flat_outputs(np.array([0.0, traj.duration]))
    for arr in (ends.velocity, ends.acceleration, ends.jerk, ends.snap):
        np.testing.assert_allclose(arr, 0.0, atol=1e-9)
    np.testing.assert_allclose([ends.yaw_rate, ends.yaw_acceleration], 0.0, atol=1e-9)


def test_excitation_is_continuous_up_to_snap(samples):
    """At every knot the segments agree in position … snap and yaw … yaw acceleration."""
    traj, _, _ = samples
    knots = np.cumsum(traj.durations)[:-1]
    left = traj.flat_outputs(knots - 1e-9)
    right = traj.flat_outputs(knots + 1e-9)
    for name in ("position", "velocity", "acceleration", "jerk", "snap",
                 "yaw", "yaw_rate", "yaw_acceleration"):
        np.testing.assert_allclose(getattr(left, name), getattr(right, name), atol=1e-6)


def test_excitation_uses_paper_polynomial_orders(samples):
    """Position segments have N = 10 coefficients and yaw segments N = 6."""
    traj, _, _ = samples
    assert traj.position_coeffs.shape[-1] == 10
    assert traj.yaw_coeffs.shape[-1] == 6


def test_excitation_is_feasible_for_every_shipped_vehicle(any_vehicle, samples):
    """Thrust, body rates, yaw acceleration, speed and rotor speeds stay inside the limits."""
    _, _, flat = samples
    state = flat_to_state(flat, any_vehicle)
    lim = any_vehicle.limits
    ratio = state.thrust / any_vehicle.hover_thrust
    assert lim.thrust_min_ratio <= ratio.min() and ratio.max() <= lim.thrust_max_ratio
    assert np.linalg.norm(state.body_rates, axis=1).max() <= lim.body_rate_max
    assert np.abs(flat.yaw_acceleration).max() <= lim.yaw_acceleration_max
    assert np.linalg.norm(flat.velocity, axis=1).max() <= lim.speed_max
    assert state.rotor_speeds_squared.min() > lim.rotor_speed_min**2
    assert state.rotor_speeds.max() < lim.rotor_speed_max


@pytest.mark.parametrize("duration", [10.0, 12.0, 45.0, 120.0])
def test_other_durations_stay_feasible_and_exciting(firefly, duration):
    """Other durations are never more aggressive than the 30 s figure, still excite, and fly."""
    base = excitation_trajectory()
    other = excitation_trajectory(ExcitationSpec(duration=duration))
    assert other.duration == pytest.approx(duration)
    peaks = []
    for traj in (base, other):
        flat = traj.flat_outputs(np.linspace(0.0, traj.duration, 8001))
        state = flat_to_state(flat, firefly)
        peaks.append((np.linalg.norm(flat.velocity, axis=1).max(),
                      np.linalg.norm(state.body_rates, axis=1).max()))
    (v0, w0), (v1, w1) = peaks
    assert 0.5 * v0 < v1 < 1.1 * v0
    assert w1 < 1.1 * w0
    assert state.rotor_speeds_squared.min() > 0.0
    assert state.rotor_speeds.max() < firefly.limits.rotor_speed_max


def test_short_excitation_is_rejected_when_ramps_do_not_fit():
    """A duration shorter than the two ramps is a clear error."""
    with pytest.raises(ValueError, match="ramp"):
        excitation_trajectory(ExcitationSpec(duration=5.0, ramp=3.0))
