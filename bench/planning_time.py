"""Planning time of the D-optimal planner: how soon it gets close to its final plan.

Per vehicle and seed (planner model = the vehicle's nominal θ): a wall-clock plan of
``--time`` s, reporting the time until the best log D-opt is 90 % of the way from the
first feasible plan to the final one (`time_to_90`, the README's figure), and the time
until it is within 90 % of the ES refinement's final log D-opt of the same seed; then,
with ``--samples`` (and an unlimited clock), a sample- and step-budgeted plan run twice
to check that the same seed gives the same plan, and its D-opt against the wall-clock one.

    python bench/planning_time.py [--vehicles firefly quad_x] [--seeds 5] [--time 30]
        [--refine-share 0.7] [--gradient] [--samples N --refine-steps N]
        [--rotor-confidence Z]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from mavsysid.planner.best_flight import refine_best
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.plan_request import check_request
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.rrbt import search_result
from mavsysid.planner.search_setup import warm_up
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle


def plan_with(config, settings: PlannerSettings, gradient: bool) -> PlanResult:
    """`mavsysid.planner.rrbt.plan` with the refinement chosen here."""
    check_request(config, settings)
    warm_up(config, settings)
    search = GraphSearch(config, settings, "dopt", None)
    search.run()
    return search_result(search, "dopt", refine_best(search, gradient=gradient))


def time_to_90(history: np.ndarray) -> float:
    """Seconds until the best log D-opt is 90 % of the way from the first plan to the final."""
    log = np.log(history[:, 1])
    target = log[-1] + 0.1 * (log[0] - log[-1])
    return float(history[np.argmax(log <= target), 0])


def parse_args() -> argparse.Namespace:
    """The benchmark's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", nargs="+", default=["firefly", "quad_x"])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--time", type=float, default=30.0)
    parser.add_argument("--refine-share", type=float, default=PlannerSettings.refine_share)
    parser.add_argument("--gradient", action="store_true",
                        help="refine with gradient steps mixed with the ES")
    parser.add_argument("--samples", type=int, default=None,
                        help="also plan with this sample budget (and --refine-steps)")
    parser.add_argument("--refine-steps", type=int, default=PlannerSettings.refine_steps)
    parser.add_argument("--rotor-confidence", type=float, default=None,
                        help="chance-constraint quantile z (default: the planner's)")
    return parser.parse_args()


def main() -> None:
    args = parse_args()
    extra = {} if args.rotor_confidence is None else {"rotor_confidence": args.rotor_confidence}
    print(f"refinement: {'gradient + ES' if args.gradient else 'ES'}, share "
          f"{args.refine_share:g}, planning {args.time:g} s, {extra}")
    for vehicle in args.vehicles:
        config = load_vehicle(vehicle)
        rows = []
        for seed in range(args.seeds):
            settings = PlannerSettings(planning_time=args.time, seed=seed,
                                       refine_share=args.refine_share, **extra)
            timed = plan_with(config, settings, args.gradient)
            row = [time_to_90(timed.stats.best_history), timed.predicted_dopt]
            line = (f"{vehicle} seed {seed}: t90 {row[0]:.1f} s, D-opt {row[1]:.3g}, "
                    f"refine {timed.stats.refine_steps}/{timed.stats.refine_accepted}")
            if args.samples is not None:
                budgeted = replace(settings, planning_time=np.inf, max_samples=args.samples,
                                   refine_steps=args.refine_steps)
                start = time.perf_counter()
                a = plan_with(config, budgeted, args.gradient)
                wall = time.perf_counter() - start
                b = plan_with(config, budgeted, args.gradient)
                same = bool(np.array_equal(a.trajectory.durations, b.trajectory.durations)
                            and a.predicted_dopt == b.predicted_dopt)
                share = np.log(a.predicted_dopt) / np.log(timed.predicted_dopt)
                row += [a.predicted_dopt, wall, same]
                line += (f" | --samples: D-opt {a.predicted_dopt:.3g} in {wall:.1f} s, "
                         f"log ratio to timed {share:.3f}, reproducible {same}")
            print(line, flush=True)
            rows.append(row)
        r = np.array(rows, dtype=float)
        summary = (f"{vehicle}: median t90 {np.median(r[:, 0]):.1f} s, median D-opt "
                   f"{np.median(r[:, 1]):.3g}")
        if args.samples is not None:
            summary += (f"; --samples median D-opt {np.median(r[:, 2]):.3g} (ratio to timed "
                        f"{np.median(r[:, 2] / r[:, 1]):.2f}), wall {np.median(r[:, 3]):.1f} s, "
                        f"reproducible {int(r[:, 4].sum())}/{len(rows)}")
        print(summary, flush=True)


if __name__ == "__main__":
    main()
