"""Fresh pose samples on a uniform grid, and rotor speeds at a delay."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.signals import fresh_pose, uniform_segments
from mavsysid.vehicle.rotation import quat_exp


def _flight(n: int = 2000, dt: float = 0.002, hold: int = 1, seed: int = 0,
            starts: tuple[int, ...] = (0,)) -> tuple[FlightData, np.ndarray, np.ndarray]:
    """A smooth flight; each pose held for ``hold`` rows (as a logger faster than its source)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt + 0.1 * dt * rng.uniform(-1, 1, n).clip(-0.4, 0.4)
    t = np.sort(t)
    p = np.column_stack([np.sin(2 * t), np.cos(3 * t), 0.5 + 0.1 * t])
    q = quat_exp(np.column_stack([0.2 * np.sin(5 * t), 0.1 * np.cos(4 * t), 0.3 * t]))
    n_rot = 1000.0 + 100.0 * np.column_stack([np.sin(t + k) for k in range(4)])
    held = (np.arange(n) // hold) * hold
    return (FlightData(t, p[held], q[held], n_rot, "held.csv", segment_starts=starts), p, q)


@pytest.mark.parametrize("hold", [1, 2, 3])
def test_fresh_pose_marks_only_exact_repeats(hold):
    """A row repeating its predecessor's pose exactly is not fresh; every other row is."""
    flight, _, _ = _flight(hold=hold)
    fresh = fresh_pose(flight.position, flight.quaternion)
    assert fresh[0]
    assert np.array_equal(np.flatnonzero(fresh), np.arange(0, len(flight), hold))


@pytest.mark.parametrize("hold", [2, 3])
def test_held_pose_is_restored_between_fresh_samples(hold):
    """Interpolating the fresh samples recovers the pose far better than the held rows."""
    flight, p, _ = _flight(hold=hold)
    (seg,) = uniform_segments(flight, 1.0)
    truth = np.column_stack([np.interp(seg.t, flight.t, p[:, j]) for j in range(3)])
    held = np.column_stack([np.interp(seg.t, flight.t, flight.position[:, j]) for j in range(3)])
    inside = (seg.t > seg.t[0] + 0.05) & (seg.t < seg.t[-1] - 0.05)
    err = np.abs(seg.position - truth)[inside].max()
    held_err = np.abs(held - truth)[inside].max()
    assert err < 0.05 * held_err, (err, held_err)
    assert np.allclose(np.linalg.norm(seg.quaternion, axis=1), 1.0)
    assert seg.fresh_fraction == pytest.approx(1.0 / hold, rel=0.01)


def test_grid_is_uniform_at_the_median_step():
    """The grid step is the log's median interval, exactly uniform."""
    flight, _, _ = _flight()
    (seg,) = uniform_segments(flight, 1.0)
    assert seg.dt == pytest.approx(float(np.median(np.diff(flight.t))))
    assert np.allclose(np.diff(seg.t), seg.dt)


@pytest.mark.parametrize("delay", [-0.013, 0.0, 0.021])
def test_rotor_speeds_at_a_delay_are_the_earlier_samples(delay):
    """rotor_speeds(δ) is n(t − δ): a pose lagging the rotors by δ pairs with earlier speeds."""
    flight, _, _ = _flight()
    (seg,) = uniform_segments(flight, 1.0)
    inside = (seg.t > seg.t[0] + 0.05) & (seg.t < seg.t[-1] - 0.05)
    expected = 1000.0 + 100.0 * np.column_stack([np.sin(seg.t - delay + k) for k in range(4)])
    assert np.allclose(seg.rotor_speeds(delay)[inside], expected[inside], atol=0.01)


def test_short_segments_are_left_out():
    """A segment shorter than min_duration gives no grid; the long one does."""
    flight, _, _ = _flight(n=3000, starts=(0, 400))
    segs = uniform_segments(flight, 2.0)
    assert len(segs) == 1
    assert segs[0].t[0] >= flight.t[400] - 1e-9
