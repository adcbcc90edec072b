"""The exact (null-space) mixer: its cost per call, and plans made with "exact" flown by it.

1. Mixer cost: µs per call of `null_space_mix` and `pseudo_inverse_mix` on random wrenches
   (both sides of the rotor limits), timed inside a numba loop (no Python dispatch), the
   best of several repeats.
2. End to end: per seed, plan a flight for the vehicle with ``allocation = "exact"``
   (`mavsysid.planner.rrbt.plan`, a sample budget), fly it in the offline simulator with
   the truth = the plan's θ, once with the exact mixer and once with the A⁺ mixer, and
   report the fraction of control ticks with a saturated rotor (or yaw given up) and the
   tracking RMS.

    python bench/exact_mixer_flight.py [--vehicle firefly] [--seeds 3] [--samples 150]
        [--budget 20] [--refine-steps 300] [--headroom 0 0.1]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numba
import numpy as np
from mavsysid.flight.offline.null_space_mixer import (
    null_space_mix,
    null_space_mixer,
    pseudo_inverse_mix,
)
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv
from mavsysid.vehicle.config import load_vehicle


@numba.njit(cache=True)
def _time_exact(W, pinv, null, normals, lower, upper, tol, lo, hi, out):
    saturated = 0
    for j in range(W.shape[0]):
        saturated += null_space_mix(W[j], pinv, null, normals, lower, upper, tol, lo, hi, out)
    return saturated


@numba.njit(cache=True)
def _time_pinv(W, pinv, lo, hi, out):
    saturated = 0
    for j in range(W.shape[0]):
        saturated += pseudo_inverse_mix(W[j], pinv, lo, hi, out)
    return saturated


def mixer_cost(name: str, count: int = 100_000, repeats: int = 5) -> None:
    """Print µs per call of both mixers for vehicle ``name``."""
    config = load_vehicle(name)
    A, pinv = allocation_matrix(config), allocation_pinv(config)
    lo, hi = config.limits.rotor_speed_min**2, config.limits.rotor_speed_max**2
    m = null_space_mixer(A, pinv, lo, hi)
    rng = np.random.default_rng(0)
    for label, widen in (("inside+outside", 0.3), ("near hover", -0.3)):
        span = hi - lo
        W = np.ascontiguousarray(
            rng.uniform(lo - widen * span, hi + widen * span, (count, A.shape[1])) @ A.T)
        out = np.empty(A.shape[1])
        best_exact = best_pinv = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            sat = _time_exact(W, m.pinv, m.null, m.normals, m.lower, m.upper, m.tolerance,
                              lo, hi, out)
            best_exact = min(best_exact, time.perf_counter() - t0)
            t0 = time.perf_counter()
            sat_p = _time_pinv(W, m.pinv, lo, hi, out)
            best_pinv = min(best_pinv, time.perf_counter() - t0)
        print(f"{name:10s} {label:15s} exact {1e6 * best_exact / count:.3f} µs/call "
              f"(saturated {sat / count:.1%}), A⁺ {1e6 * best_pinv / count:.3f} µs/call "
              f"(saturated {sat_p / count:.1%})")


def flight(name: str, seed: int, samples: int, budget: float, refine_steps: int,
           headroom: float) -> None:
    """Plan with "exact" and fly the plan with both mixers; print saturation and RMS."""
    config = replace(load_vehicle(name), allocation="exact")
    settings = PlannerSettings(budget=budget, planning_time=math.inf, max_samples=samples,
                               refine_steps=refine_steps, seed=seed,
                               rotor_headroom=headroom)
    t0 = time.perf_counter()
    result = plan(config, settings)
    planned = time.perf_counter() - t0
    row = [f"{name} seed {seed} headroom {headroom:g}: plan {result.trajectory.duration:.1f} s "
           f"in {planned:.0f} s"]
    for mode in ("exact", "pseudo_inverse"):
        sim = Simulator(replace(config, allocation=mode), true_theta=config.theta,
                        settings=SimulationSettings(seed=seed))
        flown = sim.run(result.trajectory)
        row.append(f"{mode}: saturated {100 * flown.saturated_fraction:.2f} % of ticks, "
                   f"RMS {100 * flown.position_rms:.1f} cm")
    print("; ".join(row), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicle", default="firefly")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--samples", type=int, default=150)
    parser.add_argument("--budget", type=float, default=20.0)
    parser.add_argument("--refine-steps", type=int, default=300)
    parser.add_argument("--headroom", type=float, nargs="+", default=[0.0],
                        help="planner rotor headroom(s) (PlannerSettings.rotor_headroom)")
    parser.add_argument("--no-flight", action="store_true", help="mixer cost only")
    parser.add_argument("--no-cost", action="store_true", help="flights only")
    args = parser.parse_args()
    if not args.no_cost:
        for name in dict.fromkeys([args.vehicle, "firefly", "quad_x"]):
            mixer_cost(name)
    if args.no_flight:
        return
    for headroom in args.headroom:
        for seed in range(args.seeds):
            flight(args.vehicle, seed, args.samples, args.budget, args.refine_steps, headroom)


if __name__ == "__main__":
    main()
