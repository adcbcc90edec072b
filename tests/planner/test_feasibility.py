"""Tests of segment feasibility (paper Eq. constraints, speed and rotor limits)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mavsysid.planner.feasibility import (
    CONSTRAINTS,
    check_rotor_headroom,
    check_segment,
    check_vertex_state,
    rotor_square_range,
)
from mavsysid.planner.segments import (
    Segment,
    VertexState,
    connect_fixed,
    connect_free_end,
    stop_segment,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.flatness import flat_to_state

from mavsysid.errors import InputError

# The planner's default flight volume (mavsysid.planner.settings.PlannerSettings.box), m.
BOX = np.array([-2.0, -2.0, 0.5, 2.0, 2.0, 2.5])
# Sizes of velocity … snap (m/s … m/s⁴) and yaw rate, acceleration at derivative scale 1.
POS_SCALES = np.array([1.0, 4.0, 20.0, 100.0])
YAW_SCALES = np.array([1.0, 3.0])


def _reference(seg: Segment, cfg: VehicleConfig, margin: float = 0.0) -> dict[str, bool]:
    """Dense 1 ms sampling of every limit, each tightened by ``margin`` (0.1 = 10 %)."""
    t = np.append(np.arange(0.0, seg.duration, 1e-3), seg.duration)
    flat = seg.flat_outputs(t)
    state = flat_to_state(flat, cfg)
    lim, m = cfg.limits, 1.0 - margin
    centre, half = 0.5 * (BOX[:3] + BOX[3:]), 0.5 * (BOX[3:] - BOX[:3]) * m
    ratio = state.thrust / cfg.hover_thrust
    n2 = state.rotor_speeds_squared
    return {
        "box": bool(np.all(np.abs(flat.position - centre) <= half)),
        "thrust": bool(ratio.min() >= lim.thrust_min_ratio * (1.0 + margin)
                       and ratio.max() <= lim.thrust_max_ratio * m),
        "speed": bool(np.linalg.norm(flat.velocity, axis=1).max() <= lim.speed_max * m),
        "yaw_acceleration": bool(
            np.abs(flat.yaw_acceleration).max() <= lim.yaw_acceleration_max * m),
        "body_rate": bool(np.linalg.norm(state.body_rates, axis=1).max() <= lim.body_rate_max * m),
        "rotor_speed": bool(n2.max() <= lim.rotor_speed_max**2 * m
                            and n2.min() >= lim.rotor_speed_min**2 * (1.0 + margin)),
    }


def _random_segment(seed: int, kind: str) -> Segment:
    """A free-end, fixed or stopping segment, T ∈ [0.2, 3] s, derivatives 10^[-3, 0.7] × scales.

    Drawn uniformly from the seed (hypothesis's own float draws crowd the bounds). End
    points lie ~0.4 m per second of duration from the start (per axis), yaw turns
    ~0.3 rad/s, as a planner connecting nearby samples would ask for.
    """
    rng = np.random.default_rng(seed)
    duration = rng.uniform(0.2, 3.0)
    scale = 10.0 ** rng.uniform(-3.0, 0.7)
    inner_lo, inner_hi = BOX[:3] + 0.2, BOX[3:] - 0.2

    def derivatives() -> tuple[np.ndarray, np.ndarray]:
        return (rng.normal(size=(4, 3)) * POS_SCALES[:, None] * scale,
                rng.normal(size=2) * YAW_SCALES * scale)

    p0, (dp, dy) = rng.uniform(inner_lo, inner_hi), derivatives()
    yaw0 = rng.uniform(-np.pi, np.pi)
    start = VertexState(np.vstack([p0, dp]), np.array([yaw0, *dy]))
    p1 = np.clip(p0 + rng.normal(size=3) * 0.4 * duration, inner_lo, inner_hi)
    yaw1 = yaw0 + rng.normal() * 0.3 * duration
    if kind == "free":
        return connect_free_end(start, p1, yaw1, duration)
    if kind == "fixed":
        dp, dy = derivatives()
        return connect_fixed(start, VertexState(np.vstack([p1, dp]), np.array([yaw1, *dy])),
                             duration)
    return stop_segment(start, duration)


def test_never_accepts_what_dense_sampling_rejects_and_accepts_margin_feasible(firefly):
    """Over ≥ 500 random segments: zero false accepts; ≥ 90 % of 10 %-margin-feasible accepted."""
    stats = dict.fromkeys(
        ["runs", "accepted", "feasible", "false_accepts", "margin_feasible", "margin_accepted"], 0)

    @settings(max_examples=600, derandomize=True, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(
        seed=st.integers(0, 2**32 - 1),
        kind=st.sampled_from(["free", "fixed", "stop"]),
    )
    def run(seed: int, kind: str) -> None:
        seg = _random_segment(seed, kind)
        result = check_segment(seg, firefly, BOX)
        reference = _reference(seg, firefly)
        stats["runs"] += 1
        stats["accepted"] += result.feasible
        stats["feasible"] += all(reference.values())
        if result.feasible and not all(reference.values()):
            stats["false_accepts"] += 1
        assert not (result.feasible and not all(reference.values())), reference
        assert result.feasible or result.reason in CONSTRAINTS
        if all(_reference(seg, firefly, margin=0.1).values()):
            stats["margin_feasible"] += 1
            stats["margin_accepted"] += result.feasible

    run()
    print(stats)  # the acceptance numbers, shown with -s
    assert stats["runs"] >= 500
    assert stats["false_accepts"] == 0
    assert stats["margin_feasible"] >= 100
    assert stats["margin_accepted"] >= 0.9 * stats["margin_feasible"]


@pytest.mark.parametrize("limits", [{}, {"body_rate_max": 1.5, "rotor_speed_max": 5000.0}])
def test_rejects_segments_just_past_the_dense_sampling_boundary(firefly, limits):
    """Scaled until 1 ms sampling just fails (scale to ~2e-8), a segment is rejected there too."""
    cfg = replace(firefly, limits=replace(firefly.limits, **limits))
    rng = np.random.default_rng(42)
    binding: list[str] = []
    for _ in range(30):
        start = VertexState.hover(rng.uniform(BOX[:3] + 0.5, BOX[3:] - 0.5), 0.0)
        p = start.position.copy()
        p[1:] = rng.normal(size=(4, 3)) * POS_SCALES[:, None]
        yaw = np.array([0.0, *(rng.normal(size=2) * YAW_SCALES)])
        T = rng.uniform(0.5, 2.5)

        def seg_at(a: float, p=p, yaw=yaw, T=T) -> Segment:
            q = p.copy()
            q[1:] *= a
            return stop_segment(VertexState(q, yaw * [1.0, a, a]), T)

        lo, hi = 0.0, 20.0
        if not all(_reference(seg_at(lo), cfg).values()) or all(
            _reference(seg_at(hi), cfg).values()
        ):
            continue
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if all(_reference(seg_at(mid), cfg).values()) else (lo, mid)
        assert not check_segment(seg_at(hi), cfg, BOX).feasible
        binding += [name for name, ok in _reference(seg_at(hi), cfg).items() if not ok]
    assert len(binding) >= 20
    # The sampled (non-polynomial) constraints must be among those tested at the edge.
    assert binding.count("body_rate") + binding.count("rotor_speed") >= 5


def test_polynomial_limits_are_exact(firefly):
    """A box or thrust limit a hair below the true extremum rejects; a hair above accepts."""
    start = VertexState.hover(np.array([0.0, 0.0, 1.0]), 0.0)
    p = start.position.copy()
    p[1] = [0.5, 0.0, 1.0]  # climbing, then back down: both extrema inside the segment
    seg = stop_segment(VertexState(p, start.yaw), 2.0, end_position=np.array([0.6, 0.0, 1.3]))
    t = np.linspace(0.0, seg.duration, 3_000_001)  # 0.7 µs: extrema exact to ~1e-12
    flat = seg.flat_outputs(t)
    z_max = flat.position[:, 2].max()
    tight, loose = BOX.copy(), BOX.copy()
    tight[5], loose[5] = z_max - 1e-9, z_max + 1e-9
    assert check_segment(seg, firefly, tight).reason == "box"
    assert check_segment(seg, firefly, loose).feasible
    ratio = np.linalg.norm(flat.acceleration + [0.0, 0.0, 9.81], axis=1).max() / 9.81
    for delta, feasible in ((-1e-9, False), (1e-9, True)):
        cfg = replace(firefly, limits=replace(firefly.limits, thrust_max_ratio=ratio + delta))
        result = check_segment(seg, cfg, BOX)
        assert result.feasible == feasible
        assert feasible or result.reason == "thrust"


def test_rotor_limits_catch_yaw_the_firefly_cannot_fly(firefly):
    """Hover with ψ̈ = 5 rad/s² is within |ψ̈| ≤ 2π but needs more yaw torque than the rotors give."""
    hover = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    assert check_vertex_state(hover, firefly, BOX)
    spinning = VertexState(hover.position, np.array([0.0, 0.0, 5.0]))
    assert not check_vertex_state(spinning, firefly, BOX)
    seg = connect_fixed(hover, spinning, 1.0)
    result = check_segment(seg, firefly, BOX)
    assert not result.feasible and result.reason == "rotor_speed"
    gentle = connect_fixed(hover, VertexState(hover.position, np.array([0.3, 0.0, 0.0])), 2.0)
    assert check_segment(gentle, firefly, BOX).feasible
    heavy = firefly.theta * np.array([1.0, 1.0, 1.0, 1.0, 1.0, 20.0])  # 20 × j_z
    assert not check_segment(gentle, firefly, BOX, theta=heavy).feasible


def test_vertex_state_limits(firefly):
    """Single states: outside the box, too much thrust, too fast, too much ψ̈ are rejected."""
    hover = VertexState.hover(np.array([0.0, 0.0, 1.5]), 1.0)
    assert check_vertex_state(hover, firefly, BOX)
    assert not check_vertex_state(VertexState.hover(np.array([0.0, 0.0, 3.0]), 0.0),
                                  firefly, BOX)
    for row, value in ((2, [0.0, 0.0, 9.0]), (1, [3.5, 0.0, 0.0])):
        p = hover.position.copy()
        p[row] = value
        assert not check_vertex_state(VertexState(p, hover.yaw), firefly, BOX)
    assert not check_vertex_state(VertexState(hover.position, np.array([0.0, 0.0, 7.0])),
                                  firefly, BOX)


def test_reports_the_failed_constraint_and_cost(firefly):
    """A feasible result counts its samples; an infeasible one names a constraint and a time."""
    hover = VertexState.hover(np.array([0.0, 0.0, 1.5]), 0.0)
    ok = check_segment(connect_free_end(hover, np.array([0.5, 0.5, 1.5]), 0.2, 2.0), firefly, BOX)
    assert ok and ok.reason == "" and ok.samples >= 200
    fast = check_segment(connect_free_end(hover, np.array([1.9, 1.9, 2.4]), 0.0, 0.3),
                         firefly, BOX)
    assert not fast and fast.reason in CONSTRAINTS and 0.0 <= fast.time <= 0.3


@pytest.mark.parametrize("headroom", [0.1, 0.25])
def test_rotor_headroom_keeps_sampled_rotor_speeds_inside_the_shrunk_range(firefly, headroom):
    """With headroom h no accepted segment's 1 ms rotor n² leaves [h, 1 − h] of the range."""
    lo, hi = rotor_square_range(firefly, headroom)
    span = firefly.limits.rotor_speed_max**2 - firefly.limits.rotor_speed_min**2
    assert lo == pytest.approx(headroom * span) and hi == pytest.approx((1 - headroom) * span)
    counts = {"accepted": 0, "dropped": 0}
    for seed in range(300):
        seg = _random_segment(seed, ("free", "fixed", "stop")[seed % 3])
        wide = check_segment(seg, firefly, BOX).feasible
        narrow = check_segment(seg, firefly, BOX, rotor_headroom=headroom)
        if not narrow.feasible:
            counts["dropped"] += wide
            assert not wide or narrow.reason == "rotor_speed"
            continue
        assert wide
        counts["accepted"] += 1
        t = np.append(np.arange(0.0, seg.duration, 1e-3), seg.duration)
        n2 = flat_to_state(seg.flat_outputs(t), firefly).rotor_speeds_squared
        assert lo <= n2.min() and n2.max() <= hi
    assert counts["accepted"] >= 20 and counts["dropped"] >= 5, counts


@pytest.mark.parametrize(("headroom", "problem"), [
    (0.0, None), (0.2, None), (-0.1, "fraction"), (0.5, "fraction"), (0.45, "hover speed"),
])
def test_rotor_headroom_must_leave_the_hover_speeds_in_range(firefly, headroom, problem):
    """Headroom in [0, 0.5) whose range holds the hover rotor speeds passes; else one line."""
    if problem is None:
        check_rotor_headroom(firefly, headroom)
        return
    with pytest.raises(InputError, match=problem) as error:
        check_rotor_headroom(firefly, headroom, "--rotor-headroom")
    assert str(error.value).startswith(f"--rotor-headroom {headroom:g}: ")
    assert "\n" not in str(error.value)
