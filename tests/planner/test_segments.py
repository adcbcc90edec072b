"""Tests of the 4-D polynomial segments (paper Eq. min_snap_optimization)."""

from __future__ import annotations

from math import factorial

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from mavsysid.planner.segments import (
    Segment,
    VertexState,
    connect_fixed,
    connect_free_end,
    duration_range,
    snap_cost,
    stop_segment,
    to_piecewise,
    yaw_rate_cost,
)
from mavsysid.vehicle.trajectory import PiecewisePolynomial, Trajectory

BOX_LO = np.array([-2.0, -2.0, 0.5])
BOX_HI = np.array([2.0, 2.0, 4.5])  # a 4 m cube
# Realistic sizes of velocity … snap (m/s … m/s⁴) and yaw rate, yaw acceleration.
POS_SCALES = np.array([1.0, 3.0, 15.0, 80.0])
YAW_SCALES = np.array([1.0, 3.0])


def _random_state(rng: np.random.Generator) -> VertexState:
    p = np.empty((5, 3))
    p[0] = rng.uniform(BOX_LO, BOX_HI)
    p[1:] = rng.normal(size=(4, 3)) * POS_SCALES[:, None]
    yaw = np.concatenate([[rng.uniform(-np.pi, np.pi)], rng.normal(size=2) * YAW_SCALES])
    return VertexState(p, yaw)


def _rows(t: float, n: int, k: int) -> np.ndarray:
    """d^k/dt^k of the raw monomials [1, t, …, t^(n-1)] at t."""
    return np.array([factorial(j) / factorial(j - k) * t ** (j - k) if j >= k else 0.0
                     for j in range(n)])


def _gram(T: float, n: int, r: int) -> np.ndarray:
    """∫₀^T (d^r t^i)(d^r t^j) dt in the raw monomial basis."""
    q = np.zeros((n, n))
    for i in range(r, n):
        for j in range(r, n):
            fi, fj = factorial(i) / factorial(i - r), factorial(j) / factorial(j - r)
            q[i, j] = fi * fj * T ** (i + j - 2 * r + 1) / (i + j - 2 * r + 1)
    return q


def _kkt_reference(start: np.ndarray, end_value: float, T: float, n: int, r: int):
    """Independent solve: min cᵀQc s.t. start derivatives and end value, via the KKT system."""
    m = start.size
    a = np.array([_rows(0.0, n, k) for k in range(m)] + [_rows(T, n, 0)])
    b = np.append(start, end_value)
    q = _gram(T, n, r)
    kkt = np.block([[2.0 * q, a.T], [a, np.zeros((m + 1, m + 1))]])
    sol = scipy.linalg.solve(kkt, np.concatenate([np.zeros(n), b]))
    c = sol[:n]
    return c, float(c @ q @ c)


def _assert_derivatives(actual: np.ndarray, expected: np.ndarray, T: float, tol: float) -> None:
    """Derivatives k agree to tol relative to the natural scale max_j |d_j| T^(j-k)."""
    k = np.arange(expected.shape[0]).reshape(-1, *([1] * (expected.ndim - 1)))
    unit = np.abs(expected) * T**k  # the derivatives in units of s = τ/T
    scale = max(float(unit.max()), 1e-12)
    np.testing.assert_array_less(np.abs(actual - expected) * T**k, tol * scale)


@pytest.mark.parametrize("seed", range(24))
def test_free_end_is_the_min_snap_optimum(seed: int) -> None:
    """Free-end cost matches an independent KKT solve to 1e-6; start and end conditions to 1e-9."""
    rng = np.random.default_rng(seed)
    start = _random_state(rng)
    end_p, end_yaw = rng.uniform(BOX_LO, BOX_HI), rng.uniform(-np.pi, np.pi)
    T = rng.uniform(0.3, 3.0)
    seg = connect_free_end(start, end_p, end_yaw, T)

    ref_cost = 0.0
    for axis in range(3):
        _, cost = _kkt_reference(start.position[:, axis], end_p[axis], T, 10, 4)
        ref_cost += cost
    assert snap_cost(seg) == pytest.approx(ref_cost, rel=1e-6)
    _, yaw_ref = _kkt_reference(start.yaw, end_yaw, T, 6, 1)
    assert yaw_rate_cost(seg) == pytest.approx(yaw_ref, rel=1e-6)

    s0, s1 = seg.start_state(), seg.end_state()
    _assert_derivatives(s0.position, start.position, T, 1e-9)
    _assert_derivatives(s0.yaw, start.yaw, T, 1e-9)
    scale = np.abs(start.position * T ** np.arange(5)[:, None]).max()
    assert np.abs(s1.position[0] - end_p).max() < 1e-9 * max(scale, 1.0)
    assert s1.yaw[0] == pytest.approx(end_yaw, abs=1e-9 * max(np.abs(start.yaw).max(), 1.0))


@pytest.mark.parametrize("seed", range(6))
def test_free_end_derivatives_satisfy_optimality(seed: int) -> None:
    """Perturbing the optimal free end derivatives raises both costs, symmetrically to 2nd order."""
    rng = np.random.default_rng(100 + seed)
    start = _random_state(rng)
    T = rng.uniform(0.3, 3.0)
    seg = connect_free_end(start, rng.uniform(BOX_LO, BOX_HI), rng.uniform(-1.0, 1.0), T)
    end = seg.end_state()
    same = connect_fixed(start, end, T)
    assert snap_cost(same) == pytest.approx(snap_cost(seg), rel=1e-9)
    assert yaw_rate_cost(same) == pytest.approx(yaw_rate_cost(seg), rel=1e-9)
    for _ in range(10):
        dp = np.zeros((5, 3))
        dp[1:] = rng.normal(size=(4, 3)) * POS_SCALES[:, None] * 1e-2
        dy = np.concatenate([[0.0], rng.normal(size=2) * YAW_SCALES * 1e-2])
        plus = connect_fixed(start, VertexState(end.position + dp, end.yaw + dy), T)
        minus = connect_fixed(start, VertexState(end.position - dp, end.yaw - dy), T)
        for cost in (snap_cost, yaw_rate_cost):
            j0, jp, jm = cost(seg), cost(plus), cost(minus)
            assert jp > j0 and jm > j0
            # Zero gradient: the first-order change is negligible against the second.
            assert abs(jp - jm) < 1e-4 * (jp + jm - 2.0 * j0) + 1e-10 * j0


@pytest.mark.parametrize("T", [0.1, 0.3, 1.0, 3.0, 10.0])
def test_fixed_segments_hit_both_ends(T: float) -> None:
    """Hermite segments reproduce both end states to 1e-9 for T from 0.1 s to 10 s."""
    rng = np.random.default_rng(int(T * 100))
    for _ in range(10):
        a, b = _random_state(rng), _random_state(rng)
        seg = connect_fixed(a, b, T)
        s0, s1 = seg.start_state(), seg.end_state()
        both = np.concatenate([a.position, b.position])
        for actual, expected in ((s0.position, a.position), (s1.position, b.position)):
            _assert_derivatives(actual, expected, T, 1e-9 * _spread(both, T, expected))
        for actual, expected in ((s0.yaw, a.yaw), (s1.yaw, b.yaw)):
            _assert_derivatives(actual, expected, T, 1e-9 * _spread(
                np.concatenate([a.yaw, b.yaw]), T, expected))


def _spread(both: np.ndarray, T: float, one: np.ndarray) -> float:
    """Scale of both ends' data relative to one end's (both ends set the polynomial)."""
    m = one.shape[0]
    k = np.tile(np.arange(m), 2).reshape(-1, *([1] * (both.ndim - 1)))
    kk = np.arange(m).reshape(-1, *([1] * (one.ndim - 1)))
    return float(np.abs(both * T**k).max() / max(np.abs(one * T**kk).max(), 1e-12))


@pytest.mark.parametrize("T", [0.1, 1.0, 10.0])
def test_free_end_is_well_conditioned_across_durations(T: float) -> None:
    """Free-end segments meet their start state and end pose to 1e-9 for T from 0.1 s to 10 s."""
    rng = np.random.default_rng(7)
    start = _random_state(rng)
    end_p = rng.uniform(BOX_LO, BOX_HI)
    seg = connect_free_end(start, end_p, 0.5, T)
    _assert_derivatives(seg.start_state().position, start.position, T, 1e-9)
    scale = max(np.abs(start.position * T ** np.arange(5)[:, None]).max(), 1.0)
    assert np.abs(seg.end_state().position[0] - end_p).max() < 1e-9 * scale


def test_stop_segments_end_at_rest() -> None:
    """Stop segments end with zero velocity … snap and yaw rate/acceleration, at the defaults."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        start = _random_state(rng)
        T = rng.uniform(0.5, 3.0)
        seg = stop_segment(start, T)
        end = seg.end_state()
        scale = np.abs(start.position * T ** np.arange(5)[:, None]).max()
        k = np.arange(1, 5)[:, None]
        assert np.all(np.abs(end.position[1:]) * T**k < 1e-9 * scale)
        expected = start.position[0] + start.position[1] * T / 2
        np.testing.assert_allclose(end.position[0], expected, atol=1e-9 * scale)
        assert end.yaw[0] == pytest.approx(start.yaw[0] + start.yaw[1] * T / 2, abs=1e-9)
        assert np.all(np.abs(end.yaw[1:]) < 1e-9 * np.abs(start.yaw).max() / T)
        there = stop_segment(start, T, end_position=np.array([0.1, 0.2, 1.3]))
        np.testing.assert_allclose(there.end_state().position[0], [0.1, 0.2, 1.3],
                                   atol=1e-9 * scale)


def test_costs_match_quadrature() -> None:
    """snap_cost and yaw_rate_cost equal numerical integrals of ‖p⁗‖² and ψ̇²."""
    rng = np.random.default_rng(11)
    seg = connect_fixed(_random_state(rng), _random_state(rng), 1.7)
    snap = scipy.integrate.quad(
        lambda t: float(np.sum(seg.flat_outputs(np.array([t])).snap ** 2)), 0.0, 1.7,
        limit=200, epsabs=0.0, epsrel=1e-11)[0]
    rate = scipy.integrate.quad(
        lambda t: float(seg.flat_outputs(np.array([t])).yaw_rate[0] ** 2), 0.0, 1.7,
        limit=200, epsabs=0.0, epsrel=1e-11)[0]
    assert snap_cost(seg) == pytest.approx(snap, rel=1e-8)
    assert yaw_rate_cost(seg) == pytest.approx(rate, rel=1e-8)


def test_flat_outputs_match_piecewise_polynomial() -> None:
    """A segment evaluates like the equivalent PiecewisePolynomial, holding its ends outside."""
    rng = np.random.default_rng(5)
    segs = [connect_fixed(_random_state(rng), _random_state(rng), T) for T in (0.8, 2.2)]
    t = np.linspace(-0.2, 2.4, 97)
    for seg in segs:
        pp = PiecewisePolynomial(np.array([seg.duration]), seg.position_coeffs[None],
                                 seg.yaw_coeffs[None])
        a, b = seg.flat_outputs(t), pp.flat_outputs(t)
        for name in ("position", "velocity", "acceleration", "jerk", "snap",
                     "yaw", "yaw_rate", "yaw_acceleration"):
            scale = np.abs(getattr(b, name)).max() + 1.0
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), atol=1e-12 * scale)
    chained = to_piecewise(segs)
    assert chained.duration == pytest.approx(3.0)
    assert isinstance(segs[0], Trajectory)


def test_vertex_state_and_segment_validate_shapes() -> None:
    """Wrong shapes and non-positive durations raise; hover and pose give the obvious values."""
    with pytest.raises(ValueError):
        VertexState(np.zeros((4, 3)), np.zeros(3))
    with pytest.raises(ValueError):
        Segment(0.0, np.zeros((3, 10)), np.zeros(6))
    with pytest.raises(ValueError):
        connect_free_end(VertexState.hover(np.zeros(3), 0.0), np.ones(3), 0.0, -1.0)
    h = VertexState.hover(np.array([1.0, 2.0, 3.0]), 0.5)
    np.testing.assert_array_equal(h.pose, [1.0, 2.0, 3.0, 0.5])
    assert not h.position.flags.writeable


def test_duration_range_follows_the_paper() -> None:
    """T ∈ [d / v_max, min(budget left, T_max)], None when empty."""
    assert duration_range(3.0, 3.0, 10.0, 3.0) == (1.0, 3.0)
    assert duration_range(3.0, 3.0, 2.0, 3.0) == (1.0, 2.0)
    assert duration_range(3.0, 3.0, 0.5, 3.0) is None
    assert duration_range(0.0, 3.0, 5.0, 3.0, min_duration=0.2) == (0.2, 3.0)
