"""The planner against the baselines a reviewer accepts, and the data-efficiency endpoint.

For each seed the unknown θ is drawn ±50 % around the truth (`mavsysid.experiments.
experiment.draw_prior`); that draw is the planner's model and the filter's prior. Each kind
gets the same vehicle, budget, box and limits (`mavsysid.experiments.baselines`):
"dopt" (the planner, re-planned in flight: `mavsysid.experiments.replanned_flight`, an
``--opening`` s opening flown and filtered, the rest planned from the posterior; the whole
flight flown again from the start with the same seed), "dopt_once" (the planner's single
plan from the prior), "random" (the paper's baseline), "practitioner" (the built-in
Lissajous with yaw, scaled once to the limits at the prior), "oracle" (the planner given
the true θ) and "paper_constraints" (the planner without the rotor check). Every flight is
flown in the offline simulator with the true θ (controller tuned to the truth) and filtered
from the prior.

``--mismatch`` hides physics the model lacks in the truth: rotor drag linear in rotor speed
instead of the quadratic law (c_D = 0 and k = c_T c_D n_h, the same drag in hover; errors
scored against the nominal θ, i.e. c_D's hover equivalent; `bench/mismatch_coverage.py`)
and a 40 ms motor lag whose log reports commanded speeds.

Reported (`bench/planner_baselines_summary.py`), with 95 % paired-bootstrap intervals over
seeds: D-opt ratios against the re-planned flight, flyability (> 5 % saturated ticks,
> 0.5 m RMS off path), median |error|, the planner's predicted σ at the θ it planned with
against the filter's σ, seconds to the planned flight's D-opt, seconds to σ/θ ≤ 1 % and the
paper's convergence column; the planner's targets with pass/fail. ``--json`` writes the
summary and the per-seed rows; rows are also appended to ``FILE.rows.jsonl`` as seeds end,
and ``--from-rows FILE.rows.jsonl`` summarises those (a run stopped early included).

    nice -n 10 python bench/planner_baselines.py [--seeds 100] [--budget 30] [--time 5]
        [--jobs 1] [--mismatch] [--estimator filter|estimate|auto-effects] [--json out.json]

``--estimator`` also scores ``--estimator-kinds`` (default the planned flight and the
practitioner's) by the tool's own answer (`bench/tool_estimate.py`): median |error| over
the flights not refused, refusals, and 95 % coverage.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.estimation.results import ParameterEstimate
from mavsysid.experiments.baselines import BASELINES, baseline_trajectory
from mavsysid.experiments.data_efficiency import (
    belief_history,
    seconds_to_dopt,
    seconds_to_relative_sigma,
)
from mavsysid.experiments.experiment import (
    PRIOR_SPREAD,
    draw_prior,
    estimate_history,
    filter_flight,
)
from mavsysid.experiments.replanned_flight import OPENING_BUDGET, replan_flight
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.pipeline.replanned_stream import FEEDBACK_HEADROOM
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.model_effects import effect_from_values

from bench.mismatch_coverage import CASES, truth_side
from bench.planner_baselines_summary import format_summary, summarize
from bench.tool_estimate import ESTIMATORS, tool_scores
from mavsysid.errors import MavsysidError

KINDS = ("dopt", "dopt_once", *BASELINES)
#: The hidden truth of ``--mismatch``: the hidden effects that change what is fitted.
MISMATCH = ("rotor_drag_linear", "motor_lag")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The benchmark's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--budget", type=float, default=30.0)
    parser.add_argument("--time", type=float, default=5.0, help="planning time per plan, s")
    parser.add_argument("--opening", type=float, default=OPENING_BUDGET,
                        help="budget of the re-planned flight's opening, s")
    parser.add_argument("--vehicle", default="firefly")
    parser.add_argument("--max-passes", type=int, default=10,
                        help="most back-to-back repetitions of a baseline for data efficiency")
    parser.add_argument("--jobs", type=int, default=1, help="seeds run in parallel")
    parser.add_argument("--rotor-headroom", type=float, default=FEEDBACK_HEADROOM,
                        help="rotor n² fraction every planner kind leaves free at each end, "
                        "for the controller's feedback on a vehicle with motor lag (default: "
                        "the re-planned rest's, as `stream --replan-budget` flies it)")
    parser.add_argument("--mismatch", action="store_true",
                        help="hide linear rotor drag and motor lag in the truth")
    parser.add_argument("--estimator", choices=("filter", *ESTIMATORS), default="filter",
                        help="also score --estimator-kinds by what `mavsysid estimate` runs "
                             "(estimate), or with the effects diagnose names (auto-effects)")
    parser.add_argument("--estimator-kinds", default="dopt,practitioner",
                        help="comma-separated kinds scored by --estimator")
    parser.add_argument("--json", type=Path, help="write the summary and rows here")
    parser.add_argument("--from-rows", type=Path,
                        help="summarise the rows of an earlier (perhaps unfinished) run, "
                             "FILE.rows.jsonl, instead of running (no paper column)")
    return parser.parse_args(argv)


def true_simulator(truth: VehicleConfig, mismatch: bool, seed: int) -> Simulator:
    """The true vehicle (controller tuned to the nominal θ), with the hidden effects."""
    if not mismatch:
        return Simulator(truth, true_theta=truth.theta, settings=SimulationSettings(seed=seed))
    flown, effects = truth_side(truth, MISMATCH[0])
    effects = [*effects, *(effect_from_values(name, CASES[name]) for name in MISMATCH[1:])]
    return Simulator(truth, true_theta=flown, settings=SimulationSettings(seed=seed),
                     effects=[hidden_effect(e) for e in effects])


def fly(sim: Simulator, truth: VehicleConfig, prior: VehicleConfig, planned_with: VehicleConfig,
        trajectory, directory: Path, settings: PlannerSettings) -> dict:
    """Fly ``trajectory`` on the truth, filter it from the prior; one result row.

    ``planned_with`` is the vehicle the trajectory was planned (or scaled) with: the
    predicted σ is the planner's recursion at its θ along the flown path.
    """
    result = sim.run(trajectory, directory)
    guess = prior.theta
    run = filter_flight(directory, prior,
                        ParameterEstimate(guess, np.diag((PRIOR_SPREAD * np.abs(guess)) ** 2)))
    h = run.history
    t = h.t - h.t[0]
    predicted = belief_history(planned_with, trajectory, settings).sigma[-1]
    return {"trajectory": trajectory, "duration": float(trajectory.duration),
            "reached": run.estimate.d_optimality,
            "predicted": float(belief_history(truth, trajectory, settings).dopt[-1]),
            "predicted_sigma": predicted / planned_with.theta,
            "reached_sigma": run.estimate.relative_sigma,
            "error": np.abs(run.estimate.value - truth.theta) / truth.theta,
            "saturated": float(result.saturated_fraction), "rms": float(result.position_rms),
            "to_1pct": seconds_to_relative_sigma(t, h.theta_sigma, truth.theta),
            "history": estimate_history(h.t, h.theta, h.theta_sigma)}


def planned(kind: str, prior: VehicleConfig, truth: VehicleConfig, settings: PlannerSettings,
            sim: Simulator, tmp: Path, opening: float) -> tuple:
    """(trajectory, the vehicle it was planned with, extra row fields) of one kind."""
    if kind == "dopt":
        flight = replan_flight(prior, settings, sim, tmp / "opening", opening)
        err = np.abs(flight.posterior.value / truth.theta - 1.0)
        belief = ("rest from the prior, the opening's estimate refused"
                  if flight.refusal else f"max |θ̂ err| {err.max():.0%}")
        return flight.trajectory, flight.rest_config, {
            "note": f"opening {flight.opening.trajectory.duration:.1f} s at z "
                    f"{flight.opening.settings.rotor_confidence:g}, rest at z "
                    f"{flight.rest_settings.rotor_confidence:g}, {belief}",
            "opening_refused": flight.refusal}
    if kind == "dopt_once":
        return plan(prior, settings).trajectory, prior, {"note": ""}
    model = truth if kind == "oracle" else prior
    return baseline_trajectory(kind, prior, truth, settings), model, {"note": ""}


def run_seed(args: argparse.Namespace, seed: int) -> dict:
    """Every kind for one seed, with its data-efficiency figure against the planned flight.

    A seed where some plan cannot be made is returned as ``{"seed", "failed"}``.
    """
    truth = load_vehicle(args.vehicle)
    prior = truth.with_parameters(draw_prior(truth, seed))
    settings = PlannerSettings(budget=args.budget, planning_time=args.time, seed=seed,
                               rotor_headroom=args.rotor_headroom)
    sim = true_simulator(truth, args.mismatch, seed)
    row: dict = {"seed": seed}
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="planner-baselines-") as name:
        tmp = Path(name)
        try:
            for kind in KINDS:
                trajectory, model, extra = planned(kind, prior, truth, settings, sim, tmp,
                                                   args.opening)
                row[kind] = fly(sim, truth, prior, model, trajectory, tmp / kind, settings)
                row[kind].update(extra)
                if args.estimator != "filter" and kind in args.estimator_kinds.split(","):
                    row[kind].update(tool_scores(tmp / kind, prior, truth.theta,
                                                 args.estimator))
        except MavsysidError as exc:  # refused, or a flight whose log the filter cannot read
            print(f"seed {seed}: failed: {kind}: {exc}", flush=True)
            return {"seed": seed, "failed": f"{kind}: {exc}"}
    target = row["dopt"]["predicted"]
    for kind in KINDS:
        row[kind]["to_planned"] = seconds_to_dopt(truth, row[kind].pop("trajectory"), settings,
                                                  target, args.max_passes)
    row["wall"] = time.perf_counter() - start
    print(f"seed {seed} ({row['wall']:.0f} s; {row['dopt']['note']}): " + " | ".join(
        f"{k} {row[k]['duration']:.0f} s {row[k]['reached']:.3g} sat {row[k]['saturated']:.0%}"
        f" to-planned {row[k]['to_planned']:.1f} s" for k in KINDS), flush=True)
    return row


def jsonable(value):
    """Rows and summaries with numpy arrays and floats made JSON-ready (NaN and inf: null)."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def slim(row: dict) -> dict:
    """A row without the estimate histories (kept only for the paper's column)."""
    return {k: ({kk: vv for kk, vv in v.items() if kk != "history"} if isinstance(v, dict)
                else v) for k, v in row.items()}


def run_all(args: argparse.Namespace) -> list[dict]:
    """Every seed, in parallel over ``--jobs`` processes; rows in seed order."""
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    stream = None
    if args.json is not None:
        stream = args.json.with_name(args.json.name + ".rows.jsonl").open("w")
    rows = []
    try:
        if args.jobs <= 1:
            results = (run_seed(args, s) for s in seeds)
            pool = None
        else:
            pool = ProcessPoolExecutor(max_workers=args.jobs)
            results = pool.map(run_seed, [args] * len(seeds), seeds)
        for row in results:
            rows.append(row)
            if stream is not None:
                stream.write(json.dumps(jsonable(slim(row))) + "\n")
                stream.flush()
        if pool is not None:
            pool.shutdown()
    finally:
        if stream is not None:
            stream.close()
    return rows


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.from_rows is not None:
        rows = [json.loads(line) for line in args.from_rows.read_text().splitlines() if line]
        args.seeds = len(rows)
    else:
        rows = run_all(args)
    summary = summarize(rows, KINDS, args.budget, args.max_passes,
                        load_vehicle(args.vehicle).theta)
    summary["settings"] = {k: (str(v) if isinstance(v, Path) else v)
                           for k, v in vars(args).items()}
    print(f"\n{args.seeds} seeds from {args.first_seed}, budget {args.budget:g} s, planning "
          f"{args.time:g} s per plan, opening {args.opening:g} s, {args.vehicle}, priors ±50 %"
          f"{', hidden linear rotor drag and motor lag' if args.mismatch else ''}")
    print(format_summary(summary))
    if args.json is not None:
        args.json.write_text(json.dumps(jsonable({"summary": summary,
                                                  "rows": [slim(r) for r in rows]}), indent=1))


if __name__ == "__main__":
    main()
