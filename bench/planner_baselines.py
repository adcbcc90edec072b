"""The planner against the baselines a reviewer accepts, and the data-efficiency endpoint.

For each seed the unknown θ is drawn ±50 % around the truth (`mavsysid.experiments.
experiment.draw_prior`); that draw is the planner's model and the filter's prior. Each kind
gets the same vehicle, budget, box and limits (`mavsysid.experiments.baselines`):
"dopt" (the planner), "random" (the paper's baseline), "practitioner" (the built-in
Lissajous with yaw, scaled once to the limits at the prior), "oracle" (the planner given
the true θ) and "paper_constraints" (the planner without the rotor check). Every flight is
flown in the offline simulator with the true θ (controller tuned to the truth) and filtered.

Reported, with 95 % paired-bootstrap intervals over seeds:
- median reached D-opt of each baseline over the planned flight's (> 1: planned better);
- saturation: flights with a rotor at its limit on > 5 % of control ticks, and flights
  > 0.5 m RMS off their path;
- median |error| per parameter;
- data efficiency: seconds of each baseline (repeated back to back) until its belief,
  propagated with the true θ along its nominal path, reaches the planned flight's D-opt;
  and per flight the seconds until every σ_j/θ_j ≤ 1 % (filter σ);
- the paper's convergence time (median of the estimates within 5 %), as a column only.

    nice -n 19 python bench/planner_baselines.py [--seeds 5] [--budget 30] [--time 5]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.experiments.baselines import BASELINES, baseline_trajectory
from mavsysid.experiments.data_efficiency import (
    belief_history,
    seconds_to_dopt,
    seconds_to_relative_sigma,
)
from mavsysid.experiments.evaluation import median_convergence_time
from mavsysid.experiments.evaluation_intervals import OFF_PATH_RMS, SATURATED_SHARE
from mavsysid.experiments.experiment import (
    PRIOR_SPREAD,
    draw_prior,
    estimate_history,
    filter_flight,
)
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.planner.results import PlannerSettings
from mavsysid.planner.rrbt import plan
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from scipy.stats import bootstrap

KINDS = ("dopt", *BASELINES)


def parse_args() -> argparse.Namespace:
    """The benchmark's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--budget", type=float, default=30.0)
    parser.add_argument("--time", type=float, default=5.0, help="planning time per plan, s")
    parser.add_argument("--vehicle", default="firefly")
    parser.add_argument("--max-passes", type=int, default=10,
                        help="most back-to-back repetitions of a baseline for data efficiency")
    return parser.parse_args()


def fly(truth: VehicleConfig, prior: VehicleConfig, trajectory, directory: Path, seed: int,
        settings: PlannerSettings) -> dict:
    """Fly ``trajectory`` with the true θ, filter it from the prior; one result row."""
    sim = Simulator(truth, true_theta=truth.theta,
                    settings=SimulationSettings(seed=seed)).run(trajectory, directory)
    guess = prior.theta
    run = filter_flight(directory, prior,
                        ParameterEstimate(guess, np.diag((PRIOR_SPREAD * np.abs(guess)) ** 2)))
    h = run.history
    t = h.t - h.t[0]
    return {"trajectory": trajectory, "reached": run.estimate.d_optimality,
            "predicted": float(belief_history(truth, trajectory, settings).dopt[-1]),
            "error": np.abs(run.estimate.value - truth.theta) / truth.theta,
            "saturated": float(sim.saturated_fraction), "rms": float(sim.position_rms),
            "to_1pct": seconds_to_relative_sigma(t, h.theta_sigma, truth.theta),
            "history": estimate_history(h.t, h.theta, h.theta_sigma)}


def run_seed(args: argparse.Namespace, truth: VehicleConfig, seed: int, tmp: Path) -> dict:
    """Every kind for one seed, with its data-efficiency figure against the planned flight."""
    prior = truth.with_parameters(draw_prior(truth, seed))
    settings = PlannerSettings(budget=args.budget, planning_time=args.time, seed=seed)
    row = {}
    for kind in KINDS:
        trajectory = (plan(prior, settings).trajectory if kind == "dopt"
                      else baseline_trajectory(kind, prior, truth, settings))
        row[kind] = fly(truth, prior, trajectory, tmp / f"{kind}-{seed}", seed, settings)
    target = row["dopt"]["predicted"]
    for kind in KINDS:
        row[kind]["to_planned"] = seconds_to_dopt(truth, row[kind]["trajectory"], settings,
                                                  target, args.max_passes)
    print(f"seed {seed}: " + " | ".join(
        f"{k} {row[k]['trajectory'].duration:.0f} s {row[k]['reached']:.3g} sat "
        f"{row[k]['saturated']:.0%} to-planned {row[k]['to_planned']:.1f} s" for k in KINDS),
        flush=True)
    return row


def interval(samples: tuple[np.ndarray, ...], statistic) -> tuple[float, float]:
    """95 % percentile bootstrap interval over seeds (samples resampled in pairs)."""
    if samples[0].size < 2:
        return float("nan"), float("nan")
    result = bootstrap(samples, statistic, paired=True, vectorized=False, n_resamples=2000,
                       method="percentile", rng=np.random.default_rng(0))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def column(rows: list[dict], kind: str, key: str) -> np.ndarray:
    """One figure of one kind over seeds, shape (seeds,) (or (seeds, 6))."""
    return np.array([r[kind][key] for r in rows], dtype=float)


def report_dopt(rows: list[dict]) -> None:
    """Ratios of median reached (and predicted) D-opt, baseline over planned."""
    planned = column(rows, "dopt", "reached")
    print("median reached D-opt, baseline / planned (> 1: planned better), 95 % paired "
          "bootstrap interval; predicted with the true θ along the nominal path:")
    for kind in BASELINES:
        other = column(rows, kind, "reached")
        lo, hi = interval((other, planned), lambda a, b: np.median(a) / np.median(b))
        pred = np.median(column(rows, kind, "predicted")) / np.median(
            column(rows, "dopt", "predicted"))
        print(f"  {kind:<18} {np.median(other) / np.median(planned):6.2f} ({lo:.2f}–{hi:.2f})"
              f"  predicted {pred:.2f}")


def report_flyability(rows: list[dict]) -> None:
    """Saturated and off-path flights, and median |error| per parameter."""
    print(f"flyability on the true vehicle (flights of {len(rows)}): saturating > "
          f"{100 * SATURATED_SHARE:g} % of ticks, > {OFF_PATH_RMS:g} m RMS off path, median "
          "saturated share")
    for kind in KINDS:
        sat, rms = column(rows, kind, "saturated"), column(rows, kind, "rms")
        print(f"  {kind:<18} {int(np.sum(sat > SATURATED_SHARE))}, "
              f"{int(np.sum(rms > OFF_PATH_RMS))}, {np.median(sat):.1%}")
    print("median |error| / θ per parameter (%): " + ", ".join(PARAMETER_NAMES))
    for kind in KINDS:
        err = np.median(column(rows, kind, "error"), axis=0)
        print(f"  {kind:<18} " + "  ".join(f"{100 * e:.3f}" for e in err))


def report_efficiency(args: argparse.Namespace, rows: list[dict]) -> None:
    """Seconds to the planned D-opt, seconds to σ/θ ≤ 1 %, the paper's convergence column."""
    print(f"seconds of flight to reach the planned {args.budget:g} s flight's D-opt (median, "
          f"95 % bootstrap interval; inf: not within {args.max_passes} repetitions):")
    for kind in KINDS:
        sec = column(rows, kind, "to_planned")
        sec = np.where(np.isnan(sec), np.inf, sec)
        lo, hi = interval((sec,), np.median)
        print(f"  {kind:<18} {np.median(sec):7.1f} s ({lo:.1f}–{hi:.1f}), "
              f"{np.median(sec) / args.budget:.2f}× the budget")
    print("seconds until every σ_j/θ_j ≤ 1 % (filter σ, per flight; median, flights that "
          "never get there):")
    for kind in KINDS:
        sec = column(rows, kind, "to_1pct")
        done = sec[~np.isnan(sec)]
        print(f"  {kind:<18} {np.median(done) if done.size else float('nan'):6.2f} s, "
              f"{int(np.isnan(sec).sum())} never")
    print("the paper's column: convergence time of the median estimate within 5 % (s), "
          + ", ".join(PARAMETER_NAMES))
    for kind in KINDS:
        histories = [r[kind]["history"] for r in rows]
        length = max(len(h["t"]) for h in histories)
        grid = np.arange(length) / 10.0
        ratios = np.empty((len(rows), length, 6))
        for i, (r, h) in enumerate(zip(rows, histories, strict=True)):
            theta = np.asarray(h["theta"])
            ratios[i, :len(theta)], ratios[i, len(theta):] = theta, theta[-1]
            ratios[i] /= r["truth"]
        conv = median_convergence_time(grid, ratios)
        print(f"  {kind:<18} " + "  ".join(f"{c:.2f}" for c in conv))


def main() -> None:
    args = parse_args()
    truth = load_vehicle(args.vehicle)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            row = run_seed(args, truth, seed, Path(tmp))
            row["truth"] = truth.theta
            rows.append(row)
    print(f"\n{args.seeds} seeds, budget {args.budget:g} s, planning {args.time:g} s per plan, "
          f"{args.vehicle}, priors ±50 %")
    report_dopt(rows)
    report_flyability(rows)
    report_efficiency(args, rows)


if __name__ == "__main__":
    main()
