"""How `mavsysid evaluate`'s headline figures move with the number of experiments and the
filter's starting σ.

Flies experiments 0 … n−1 exactly as `mavsysid evaluate --n N --samples S --refine-steps R`
does (same specs, seeds, plans and simulated flights), keeps their pose logs in
``--workdir`` (a re-run flies only what is missing), then re-runs the EKF from a starting
σ of each ``--sigmas`` fraction of the guess and scores the flights with evaluate's own
statistics (`mavsysid.experiments.evaluation_intervals.headline_intervals` over records shaped as
evaluate's).

    python bench/filter_prior_sensitivity.py --n 100 --workdir /tmp/prior-sensitivity
        [--sigmas 0.5,0.369,0.29,0.2] [--first 20] [--samples 8000] [--refine-steps 100000]
        [--workers 2]
"""

from __future__ import annotations

import argparse
import shutil
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.experiments.evaluate_job import make_specs
from mavsysid.experiments.evaluation_intervals import headline_intervals
from mavsysid.experiments.experiment import (
    KINDS,
    ExperimentSpec,
    draw_prior,
    estimate_history,
    filter_flight,
    fly_plan,
)
from mavsysid.vehicle.config import load_vehicle


def _flight_dir(workdir: Path, spec: ExperimentSpec, kind: str) -> Path:
    return workdir / f"{spec.index:03d}-{kind}"


def fly(spec: ExperimentSpec, workdir: Path) -> None:
    """Both flights of one experiment (first iteration), as evaluate flies them.

    A flight is written to a scratch folder and renamed when complete, so an
    interrupted run re-flies only what is missing.
    """
    truth = load_vehicle(spec.vehicle)
    model = truth.with_parameters(draw_prior(truth, spec.seed))
    for kind in KINDS:
        directory = _flight_dir(workdir, spec, kind)
        if directory.exists():
            continue
        scratch = directory.with_name(directory.name + ".partial")
        shutil.rmtree(scratch, ignore_errors=True)
        fly_plan(spec, truth, model, kind, 1, scratch)
        scratch.rename(directory)


def record(spec: ExperimentSpec, workdir: Path, sigma: float) -> dict[str, Any]:
    """Evaluate's record fields the headline figures read, filtered from σ = sigma·|guess|."""
    truth = load_vehicle(spec.vehicle)
    guess = draw_prior(truth, spec.seed)
    model = truth.with_parameters(guess)
    prior = ParameterEstimate(guess, np.diag((sigma * np.abs(guess)) ** 2))
    flights = []
    for kind in KINDS:
        run = filter_flight(_flight_dir(workdir, spec, kind), model, prior)
        h = run.history
        flights.append({"kind": kind, "iteration": 1, "reached_dopt": run.estimate.d_optimality,
                        "history": estimate_history(h.t, h.theta, h.theta_sigma)})
    return {"truth": truth.theta.tolist(), "flights": flights}


def score(records: list[dict[str, Any]]) -> str:
    """The two headline figures with evaluate's 95 % paired-bootstrap intervals."""
    h = headline_intervals(records)
    (r_lo, r_hi), (c_lo, c_hi) = h.dopt_ratio_interval, h.convergence_reduction_interval
    return (f"D-opt ratio {h.dopt_ratio:.2f} ({r_lo:.2f}–{r_hi:.2f}), convergence reduction "
            f"{100 * h.convergence_reduction:.0f} % ({100 * c_lo:.0f}–{100 * c_hi:.0f} %)")


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
        for sigma in (float(x) for x in args.sigmas.split(",")):
            records = list(pool.map(record, specs, [args.workdir] * len(specs),
                                    [sigma] * len(specs)))
            line = f"starting σ {sigma:g} of the guess: {args.n} experiments, {score(records)}"
            if 2 <= args.first < args.n:
                line += f"; first {args.first}: {score(records[:args.first])}"
            print(line, flush=True)


if __name__ == "__main__":
    main()
