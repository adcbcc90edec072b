"""Exact rotor feasibility: slabs of the allocation polytope against an LP.

Per shipped vehicle: agreement of the slab test and the HiGHS LP on seeded random
wrenches (half within 10⁻⁵…10⁻² of the boundary), the time per wrench of each (numba
single wrench, numpy batch, one LP), the planner's segment check with A⁺ and with the
exact polytope (µs per segment) against a dense 1 ms block-LP check of the same segment,
and on the hexacopter the yaw torque gained over A⁺ at hover thrust.

    nice python bench/allocation_feasibility.py [--wrenches 10000] [--segments 200]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.planner.feasibility import check_segment
from mavsysid.vehicle.allocation import allocation_matrix
from mavsysid.vehicle.allocation_polytope import (
    pseudo_inverse_slabs,
    wrench_reachable_lp,
    zonotope_slabs,
)
from mavsysid.vehicle.config import SHIPPED_VEHICLES, load_vehicle
from scipy.optimize import linprog

from tests.planner.test_feasibility_exact import BOX, dense_lp_feasible, random_segment
from tests.vehicle.test_allocation_polytope import max_yaw_slabs, random_wrenches


@numba.njit(cache=True)
def _inside(normals: np.ndarray, lower: np.ndarray, upper: np.ndarray, w: np.ndarray) -> bool:
    for i in range(normals.shape[0]):
        v = (normals[i, 0] * w[0] + normals[i, 1] * w[1] + normals[i, 2] * w[2]
             + normals[i, 3] * w[3])
        if v > upper[i] or v < lower[i]:
            return False
    return True


def _per_call(fn, items, repeats: int = 3) -> float:
    """Best of ``repeats`` mean times per call, µs (the 2 cores are shared)."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for item in items:
            fn(item)
        best = min(best, (time.perf_counter() - start) / len(items) * 1e6)
    return best


def wrenches(name: str, count: int) -> None:
    cfg = load_vehicle(name)
    A, hi = allocation_matrix(cfg), cfg.limits.rotor_speed_max**2
    lo = 0.05 * hi
    slabs = zonotope_slabs(A, lo, hi)
    w = random_wrenches(A, lo, hi, slabs, count, np.random.default_rng(1))
    start = time.perf_counter()
    fast = slabs.contains(w)
    batch = (time.perf_counter() - start) / count * 1e6
    _inside(slabs.normals, slabs.lower, slabs.upper, w[0])
    single = _per_call(lambda x: _inside(slabs.normals, slabs.lower, slabs.upper, x), w)
    lp_time = _per_call(lambda x: wrench_reachable_lp(A, lo, hi, x), w[:500], repeats=1)
    lp = np.array([wrench_reachable_lp(A, lo, hi, x) for x in w])
    print(f"{name:10s} slabs {slabs.normals.shape[0]:3d}  agree {int((fast == lp).sum())}/{count}"
          f"  per wrench: numba {single:.2f} µs (call from Python), numpy batch {batch:.3f} µs,"
          f" LP {lp_time:.0f} µs")


def segments(name: str, count: int) -> None:
    base = load_vehicle(name)
    cfg = replace(replace(base, allocation="exact"), limits=replace(
        base.limits, body_rate_max=100.0, yaw_acceleration_max=1e3, speed_max=100.0,
        thrust_min_ratio=0.01, thrust_max_ratio=10.0))
    pinv_cfg = replace(cfg, allocation="pseudo_inverse")
    rng = np.random.default_rng(7)
    segs = [random_segment(rng) for _ in range(count)]
    for c in (cfg, pinv_cfg):
        check_segment(segs[0], c, BOX)
    t_exact = _per_call(lambda s: check_segment(s, cfg, BOX), segs)
    t_pinv = _per_call(lambda s: check_segment(s, pinv_cfg, BOX), segs)
    accepted = [s for s in segs if check_segment(s, cfg, BOX).feasible]
    start = time.perf_counter()
    false = sum(not dense_lp_feasible(s, cfg) for s in accepted)
    t_dense = (time.perf_counter() - start) / max(1, len(accepted)) * 1e6
    pinv_ok = sum(check_segment(s, pinv_cfg, BOX).feasible for s in segs)
    print(f"{name:10s} segments {count}: accepted exact {len(accepted)}, A⁺ {pinv_ok}; "
          f"false accepts vs dense LP {false}; per segment: exact {t_exact:.0f} µs, "
          f"A⁺ {t_pinv:.0f} µs, dense 1 ms block LP {t_dense:.0f} µs")


def yaw_gain() -> None:
    cfg = load_vehicle("firefly")
    A, hi = allocation_matrix(cfg), cfg.limits.rotor_speed_max**2
    exact, pinv = zonotope_slabs(A, 0.0, hi), pseudo_inverse_slabs(A, 0.0, hi)
    thrust = cfg.hover_thrust
    roll_max = linprog(-A[1], A_eq=A[[0, 2, 3]], b_eq=[thrust, 0, 0], bounds=(0, hi),
                       method="highs").x @ A[1]
    rows = []
    for fraction in (0.2, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9):
        e, p = (max_yaw_slabs(s, thrust, fraction * roll_max) for s in (exact, pinv))
        rows.append(f"{fraction:.0%}: {e / p:.2f}×" if p > 0 else f"{fraction:.0%}: A⁺ none")
    print("firefly max yaw torque exact/A⁺ at hover thrust, roll torque as a fraction of "
          "the exact maximum:", ", ".join(rows))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wrenches", type=int, default=10000)
    parser.add_argument("--segments", type=int, default=200)
    args = parser.parse_args()
    for name in SHIPPED_VEHICLES:
        wrenches(name, args.wrenches)
    for name in SHIPPED_VEHICLES:
        segments(name, args.segments)
    yaw_gain()


if __name__ == "__main__":
    main()
