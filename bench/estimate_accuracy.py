"""Estimation accuracy over many seeds (target: median < 5 %, worst < 10 % on the core, 3σ).

For each vehicle and seed: simulate the built-in 30 s excitation (docs/architecture.md noise), draw
the prior ±50 % around the truth, estimate. Prints per parameter the median and worst
relative error of the filter and of the refined estimate, and the share of (seed,
parameter) pairs within 3σ; then refined vs filter on 10 s flights.

    python bench/estimate_accuracy.py [--seeds 10]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from mavsysid.estimation.filter.estimator import estimate_parameters
from mavsysid.estimation.readers import load_flight
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle


def run(name: str, seed: int, duration: float, tmp: Path):
    truth = load_vehicle(name)
    directory = tmp / f"{name}-{seed}-{duration:g}"
    Simulator(truth, settings=SimulationSettings(seed=seed)).run(
        excitation_trajectory(ExcitationSpec(duration=duration)), directory)
    rng = np.random.default_rng(10_000 + seed)
    prior = truth.with_parameters(truth.theta * (1.0 + rng.uniform(-0.5, 0.5, 6)))
    result = estimate_parameters(load_flight(directory / "pose.csv", prior), prior)
    return truth.theta, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    header = "  ".join(f"{n:>13}" for n in PARAMETER_NAMES)
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("firefly", "quad_x", "micro_quad"):
            filt, ref, z = [], [], []
            for seed in range(args.seeds):
                truth, result = run(name, seed, 30.0, Path(tmp))
                filt.append(np.abs(result.filtered.value / truth - 1.0))
                ref.append(np.abs(result.refined.value / truth - 1.0))
                z.append(np.abs(result.refined.value - truth) / result.refined.sigma)
            filt, ref, z = (np.array(a) for a in (filt, ref, z))
            print(f"\n{name}, 30 s excitation, {args.seeds} seeds, priors ±50 %")
            print(f"{'':24}{header}")
            for label, arr in (("filter median %", filt), ("filter worst %", filt),
                               ("refined median %", ref), ("refined worst %", ref)):
                stat = np.median(arr, 0) if "median" in label else arr.max(0)
                print(f"{label:<24}" + "  ".join(f"{100 * v:>13.4f}" for v in stat))
            zf = np.array([np.abs(r) for r in z])
            print(f"refined |error| < 3σ: {100 * np.mean(zf < 3):.0f} % of (seed, parameter) pairs"
                  f" (largest |error|/σ {zf.max():.2f})")
        filt, ref = [], []
        for seed in range(args.seeds):
            truth, result = run("firefly", seed, 10.0, Path(tmp))
            filt.append(np.abs(result.filtered.value / truth - 1.0))
            ref.append(np.abs(result.refined.value / truth - 1.0))
        ratio = np.median(ref, 0) / np.median(filt, 0)
        print(f"\nfirefly, 10 s flights, {args.seeds} seeds: refined / filter median error")
        print(f"{'':24}{header}")
        print(f"{'ratio':<24}" + "  ".join(f"{v:>13.3f}" for v in ratio))


if __name__ == "__main__":
    main()
