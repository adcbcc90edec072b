"""The exact (null-space) mixer against an independent LP, and the controller's choice of mixer."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.flight.offline.controller import GeometricController
from mavsysid.flight.offline.null_space_mixer import (
    null_space_mix,
    null_space_mixer,
    pseudo_inverse_mix,
)
from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv
from mavsysid.vehicle.allocation_polytope import wrench_reachable_lp
from mavsysid.vehicle.config import SHIPPED_VEHICLES, load_vehicle
from scipy.optimize import linprog

RELATIVE = 1e-6


def _random_wrenches(A: np.ndarray, lo: float, hi: float, count: int,
                     rng: np.random.Generator) -> np.ndarray:
    """Wrenches A n²: half from a box 30 % wider than the rotor box (both sides of the
    boundary), half with some rotors exactly at a limit (reachable, on a face)."""
    k = A.shape[1]
    span = hi - lo
    n2 = rng.uniform(lo - 0.3 * span, hi + 0.3 * span, (count, k))
    face = np.arange(count) % 2 == 1
    at_limit = rng.random((count, k)) < 0.4
    inside = rng.uniform(lo, hi, (count, k))
    inside[at_limit] = rng.choice([lo, hi], size=at_limit.sum())
    n2[face] = inside[face]
    return n2 @ A.T


def _largest_yaw_share_lp(A: np.ndarray, lo: float, hi: float, w: np.ndarray) -> float | None:
    """Largest s ∈ [0, 1] with [T, τ_x, τ_y, s τ_z] reachable (HiGHS LP); None if none is."""
    k = A.shape[1]
    d = np.abs(A).max(axis=1)
    M = np.hstack([A / d[:, None] * (hi - lo), -(np.eye(4)[:, 3] * w[3] / d)[:, None]])
    rhs = (np.r_[w[:3], 0.0] - A.sum(axis=1) * lo) / d
    c = np.zeros(k + 1)
    c[-1] = -1.0
    res = linprog(c, A_eq=M, b_eq=rhs, bounds=(0.0, 1.0), method="highs")
    return float(res.x[-1]) if res.status == 0 else None


def _check_vehicle(name: str, count: int, seed: int) -> None:
    config = replace(load_vehicle(name), allocation="exact")
    A, pinv = allocation_matrix(config), allocation_pinv(config)
    lo, hi = config.limits.rotor_speed_min**2, config.limits.rotor_speed_max**2
    m = null_space_mixer(A, pinv, lo, hi)
    args = (m.pinv, m.null, m.normals, m.lower, m.upper, m.tolerance, m.n2_min, m.n2_max)
    row_range = np.abs(A).sum(axis=1) * hi  # each wrench component's full range
    k = A.shape[1]
    out, out_pinv = np.empty(k), np.empty(k)
    rng = np.random.default_rng(seed)
    counts = {"reachable": 0, "yaw_given_up": 0, "as_pinv": 0}
    for w in _random_wrenches(A, lo, hi, count, rng):
        saturated = null_space_mix(w, *args, out)
        n2 = out**2
        assert np.all(n2 >= lo - 1e-9 * hi) and np.all(n2 <= hi * (1 + 1e-9))
        if wrench_reachable_lp(A, lo, hi, w):
            counts["reachable"] += 1
            np.testing.assert_array_less(np.abs(A @ n2 - w) / row_range, RELATIVE)
            continue
        assert saturated
        s = _largest_yaw_share_lp(A, lo, hi, w)
        if s is None:
            counts["as_pinv"] += 1
            pseudo_inverse_mix(w, m.pinv, m.n2_min, m.n2_max, out_pinv)
            np.testing.assert_array_equal(out, out_pinv)
            continue
        counts["yaw_given_up"] += 1
        target = np.r_[w[:3], s * w[3]]
        np.testing.assert_array_less(np.abs(A @ n2 - target) / row_range, RELATIVE)
    # The sample must exercise every branch (a hexacopter's and a quadrotor's alike).
    assert min(counts.values()) > count // 50, counts


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_mixer_matches_lp(name: str) -> None:
    """A few hundred wrenches per shipped vehicle: the fast version of the check below."""
    _check_vehicle(name, 400, seed=1)


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_mixer_matches_lp_on_two_thousand_wrenches(name: str) -> None:
    """Reachable (LP) wrenches are produced exactly inside the rotor box; unreachable ones
    lose the least yaw torque that makes them reachable, or are mixed as by A⁺."""
    _check_vehicle(name, 2_000, seed=2)


def test_controller_picks_mixer_by_config() -> None:
    """With "exact" the hexacopter keeps the full yaw torque where A⁺ gives some up."""
    firefly = load_vehicle("firefly")
    pinv_ctl = GeometricController(replace(firefly, allocation="pseudo_inverse"))
    exact_ctl = GeometricController(replace(firefly, allocation="exact"))
    x = np.zeros(13)
    x[6] = 1.0
    rng = np.random.default_rng(3)
    out_pinv, out_exact = np.empty(6), np.empty(6)
    A = allocation_matrix(firefly)
    differs = 0
    for _ in range(200):
        x[10:13] = rng.normal(scale=0.065, size=3)  # body rates: torques near the yaw limit
        ref = np.zeros(16)
        sat_pinv = pinv_ctl.command(x, ref, out_pinv)
        sat_exact = exact_ctl.command(x, ref, out_exact)
        if sat_pinv and not sat_exact:
            differs += 1
            # The same thrust and roll/pitch torque, with the yaw torque A⁺ gave up.
            w_exact, w_pinv = A @ out_exact**2, A @ out_pinv**2
            np.testing.assert_allclose(w_exact[:3], w_pinv[:3], rtol=1e-9, atol=1e-12)
            assert abs(w_exact[3]) > abs(w_pinv[3])
        if not sat_pinv:
            np.testing.assert_allclose(out_exact, out_pinv, rtol=1e-12)
    assert differs > 0


@pytest.mark.slow
def test_exact_plans_fly_with_fewer_saturated_ticks() -> None:
    """Firefly plans made with "exact" (`plan`'s default rotor headroom), truth = the plan's θ: the
    exact mixer saturates on at most 1 % of ticks in the median flight, and on fewer ticks
    in all than the A⁺ mixer flying the same plans."""
    from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
    from mavsysid.planner.rrbt import plan
    from mavsysid.planner.settings import PlannerSettings

    from mavsysid.cli.plan import DEFAULT_ROTOR_HEADROOM

    config = replace(load_vehicle("firefly"), allocation="exact")
    fractions: dict[str, list[float]] = {"exact": [], "pseudo_inverse": []}
    for seed in range(5):
        settings = PlannerSettings(budget=20.0, planning_time=np.inf, max_samples=150,
                                   refine_steps=300, seed=seed,
                                   rotor_headroom=DEFAULT_ROTOR_HEADROOM)
        trajectory = plan(config, settings).trajectory
        for mode, values in fractions.items():
            sim = Simulator(replace(config, allocation=mode), true_theta=config.theta,
                            settings=SimulationSettings(seed=seed))
            values.append(sim.run(trajectory).saturated_fraction)
    assert np.median(fractions["exact"]) <= 0.01, fractions
    assert sum(fractions["exact"]) < sum(fractions["pseudo_inverse"]), fractions
