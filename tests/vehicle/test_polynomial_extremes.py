"""Exact extremes of polynomial segments (`mavsysid.vehicle.polynomial_extremes`) against a
dense sampling of the same polynomials, evaluated independently here."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.kinematic_limits import KINEMATIC_FIELDS, polynomial_peaks
from mavsysid.vehicle.polynomial_extremes import EXTREME_GRID, QUANTITIES, segment_extremes

P = np.polynomial.polynomial
#: Signed quantities. The smallest value of a norm or an absolute value sits at or near a
#: kink (0, or √(ε² + c τ²)), where a sampling is off by far more than (ω Δt)²/8: only the
#: bound is checked there.
SIGNED = {"x", "y", "z", "vertical_speed", "vertical_accel", "yaw"}
#: Rounding: the two sides evaluate the same values in a different order.
ROUNDING = 1e-13
#: Dense samples per segment: a sampled peak is within a relative (ω Δt)²/8 of the true one,
#: ω ≲ 16/T for these degrees, so 2·10⁵ samples leave ≲ 10⁻⁹.
DENSE = 200_001


def _segment(seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """A seeded degree-9 position / degree-5 yaw segment whose derivatives are O(1)."""
    rng = np.random.default_rng(seed)
    duration = float(rng.uniform(0.2, 10.0))
    scale = duration ** -np.arange(10.0)
    pc = rng.normal(size=(3, 10)) * scale * rng.uniform(0.5, 3.0)
    yc = rng.normal(size=6) * scale[:6]
    return pc, yc, duration


def _dense(pc: np.ndarray, yc: np.ndarray, duration: float) -> dict[str, np.ndarray]:
    """Every quantity of `QUANTITIES` on a dense grid, straight from its definition."""
    t = np.linspace(0.0, duration, DENSE)
    d = [np.array([P.polyval(t, P.polyder(c, k)) for c in pc]) for k in range(4)]
    p, v, a, j = d
    y1, y2 = P.polyval(t, P.polyder(yc)), P.polyval(t, P.polyder(yc, 2))
    return {
        "x": p[0], "y": p[1], "z": p[2], "speed": np.linalg.norm(v, axis=0),
        "speed_xy": np.hypot(v[0], v[1]), "vertical_speed": v[2],
        "thrust": np.sqrt(a[0] ** 2 + a[1] ** 2 + (a[2] + GRAVITY) ** 2),
        "accel_xy": np.hypot(a[0], a[1]), "vertical_accel": a[2],
        "jerk": np.linalg.norm(j, axis=0), "jerk_xy": np.hypot(j[0], j[1]),
        "jerk_z": np.abs(j[2]), "tilt": np.arctan2(np.hypot(a[0], a[1]), a[2] + GRAVITY),
        "yaw": P.polyval(t, yc), "yaw_rate": np.abs(y1), "yaw_acceleration": np.abs(y2),
    }


@pytest.mark.parametrize("seed", range(6))
def test_exact_extremes_bound_and_match_a_dense_sampling(seed: int) -> None:
    pc, yc, duration = _segment(seed)
    exact = segment_extremes(pc, yc, duration)
    dense = _dense(pc, yc, duration)
    assert set(exact) == set(QUANTITIES)
    for name in QUANTITIES:
        tau, values = exact[name]
        assert np.all((tau >= 0.0) & (tau <= duration)), name
        for sign in (1.0, -1.0):  # the largest and the smallest value
            mine, sampled = np.max(sign * values), np.max(sign * dense[name])
            tol = 1e-9 * max(1.0, abs(sampled))
            assert mine >= sampled - ROUNDING * max(1.0, abs(sampled)), (name, sign, mine,
                                                                         sampled)
            if sign > 0.0 or name in SIGNED:
                assert mine - sampled <= tol, (name, sign, mine, sampled)


def test_the_roots_matter_beyond_the_grid() -> None:
    """The grid alone misses peaks by more than the tolerance: the roots are what's exact."""
    misses = 0.0
    for seed in range(6):
        pc, yc, duration = _segment(seed)
        exact = segment_extremes(pc, yc, duration)
        for name in QUANTITIES:
            values = exact[name][1]
            grid_only = np.max(values[:EXTREME_GRID])
            misses = max(misses, (np.max(values) - grid_only) / max(1.0, abs(np.max(values))))
    assert misses > 1e-4


def test_polynomial_peaks_take_the_largest_over_segments() -> None:
    segments = [_segment(seed) for seed in (11, 12, 13)]
    pc = np.array([s[0] for s in segments])
    yc = np.array([s[1] for s in segments])
    durations = np.array([s[2] for s in segments])
    peaks = polynomial_peaks(pc, yc, durations)
    dense = [_dense(*s) for s in segments]
    expected = {
        "speed_xy": max(np.max(d["speed_xy"]) for d in dense),
        "climb": max(0.0, *(np.max(d["vertical_speed"]) for d in dense)),
        "descent": max(0.0, *(np.max(-d["vertical_speed"]) for d in dense)),
        "accel_xy": max(np.max(d["accel_xy"]) for d in dense),
        "accel_up": max(0.0, *(np.max(d["vertical_accel"]) for d in dense)),
        "accel_down": max(0.0, *(np.max(-d["vertical_accel"]) for d in dense)),
        "jerk_xy": max(np.max(d["jerk_xy"]) for d in dense),
        "jerk_z": max(np.max(d["jerk_z"]) for d in dense),
        "jerk": max(np.max(d["jerk"]) for d in dense),
        "tilt": max(np.max(d["tilt"]) for d in dense),
        "yaw_rate": max(np.max(d["yaw_rate"]) for d in dense),
        "yaw_acceleration": max(np.max(d["yaw_acceleration"]) for d in dense),
    }
    assert set(expected) == set(KINEMATIC_FIELDS)
    for name, sampled in expected.items():
        mine = getattr(peaks, name)
        scale = max(1.0, sampled)
        assert sampled - ROUNDING * scale <= mine <= sampled + 1e-9 * scale, (name, mine,
                                                                              sampled)
