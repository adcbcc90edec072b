"""How `mavsysid evaluate`'s headline figures move with the number of experiments and the
filter's starting σ.

Flies experiments 0 … n−1 exactly as `mavsysid evaluate --n N --samples S --refine-steps R`
does (same specs, seeds, plans and simulated flights), keeps their pose logs in
``--workdir`` (a re-run flies only what is missing), then re-runs the EKF from a starting
σ of each ``--sigmas`` fraction of the guess and scores the flights with evaluate's own
statistics (`mavsysid.evaluation_intervals.headline_figures`, paired bootstrap over
experiments).

    python bench/filter_prior_sensitivity.py --n 100 --workdir /tmp/prior-sensitivity
        [--sigmas 0.5,0.369,0.29,0.2] [--first 20] [--samples 8000] [--refine-steps 100000]
        [--workers 2]
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.stats import bootstrap

from estimation.results import ParameterEstimate
from flight.simulator import SimulationSettings, Simulator
from mavsysid.evaluate import make_specs
from mavsysid.evaluation_intervals import headline_figures
from mavsysid.experiment import (
    KINDS,
    ExperimentSpec,
    _filter,
    _planner_settings,
    controller_config,
    draw_prior,
)
from planner.baseline import plan_random
from planner.rrbt import plan
from vehicle.config import load_vehicle

#: Flight-time grid of the estimate histories, s (evaluate's 10 Hz).
GRID = np.round(np.arange(0.0, 27.95, 0.1), 6)


def fly(spec: ExperimentSpec, workdir: Path) -> None:
    """Both flights of one experiment, as `mavsysid.experiment._fly` flies them."""
    truth = load_vehicle(spec.vehicle)
    guess = draw_prior(truth, spec.seed)
    model = truth.with_parameters(guess)
    seed = spec.seed * 100 + 1
    for kind, planner in (("dopt", plan), ("random", plan_random)):
        directory = workdir / f"{spec.index:03d}-{kind}"
        if (directory / "guess.json").exists():
            continue
        result = planner(model, _planner_settings(spec, seed))
        Simulator(controller_config(spec.controller_model, truth, model),
                  true_theta=truth.theta, settings=SimulationSettings(seed=seed)
                  ).run(result.trajectory, directory)
        (directory / "guess.json").write_text(json.dumps(guess.tolist()))


def filtered(directory: Path, sigma: float, truth_theta: np.ndarray, vehicle: str
             ) -> tuple[np.ndarray, float]:
    """Estimate / truth on `GRID` and the reached D-opt, from a starting σ = sigma·|guess|."""
    guess = np.array(json.loads((directory / "guess.json").read_text()))
    model = load_vehicle(vehicle).with_parameters(guess)
    run = _filter(directory, model, ParameterEstimate(guess, np.diag((sigma * np.abs(guess)) ** 2)))
    t = run.history.t - run.history.t[0]
    ratios = np.column_stack([np.interp(GRID, t, run.history.theta[:, j]) for j in range(6)])
    return ratios / truth_theta, run.estimate.d_optimality


def score(dopt: dict[str, np.ndarray], ratios: dict[str, np.ndarray]) -> str:
    """The two headline figures with their 95 % paired-bootstrap intervals."""
    count = len(dopt["dopt"])

    def statistic(index: np.ndarray) -> np.ndarray:
        i = np.asarray(index, dtype=int)
        return headline_figures(GRID, {k: v[i] for k, v in dopt.items()},
                                {k: v[i] for k, v in ratios.items()})

    point = statistic(np.arange(count))
    ci = bootstrap((np.arange(count),), statistic, vectorized=False, n_resamples=1000,
                   method="percentile", rng=np.random.default_rng(0)).confidence_interval
    return (f"D-opt ratio {point[0]:.2f} ({ci.low[0]:.2f}–{ci.high[0]:.2f}), convergence "
            f"reduction {100 * point[1]:.0f} % ({100 * ci.low[1]:.0f}–{100 * ci.high[1]:.0f} %)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument("--workdir", type=Path, required=True)
    parser.add_argument("--sigmas", default="0.5,0.369,0.29,0.2")
    parser.add_argument("--first", type=int, default=20,
                        help="also score the first N experiments alone")
    parser.add_argument("--samples", type=int, default=8000)
    parser.add_argument("--refine-steps", type=int, default=100_000)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    specs = make_specs(args.n, samples=args.samples, refine_steps=args.refine_steps)
    args.workdir.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(args.workers) as pool:
        list(pool.map(fly, specs, [args.workdir] * len(specs)))
    truth = load_vehicle(specs[0].vehicle).theta
    for sigma in (float(x) for x in args.sigmas.split(",")):
        with ProcessPoolExecutor(args.workers) as pool:
            runs = {k: list(pool.map(filtered, [args.workdir / f"{s.index:03d}-{k}"
                                                for s in specs],
                                     [sigma] * len(specs), [truth] * len(specs),
                                     [specs[0].vehicle] * len(specs)))
                    for k in KINDS}
        ratios = {k: np.array([r for r, _ in v]) for k, v in runs.items()}
        dopt = {k: np.array([d for _, d in v]) for k, v in runs.items()}
        line = f"starting σ {sigma:g} of the guess: {args.n} experiments, {score(dopt, ratios)}"
        if 2 <= args.first < args.n:
            first = score({k: v[:args.first] for k, v in dopt.items()},
                          {k: v[:args.first] for k, v in ratios.items()})
            line += f"; first {args.first}: {first}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
