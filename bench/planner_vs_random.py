"""The paper's comparison: planned (D-opt) vs random calibration flights (floor: 4.4× in D-opt).

For each seed the planner's model θ (and the estimator's prior) is drawn ±50 % around the
truth, as in the paper. Both planners get the same budget and planning time; both
flights are flown in the offline simulator with the true θ and the filter is run on the
logs. Reported: median D-opt (SI) predicted and reached by the estimator, their ratio,
the prediction error, and how many seconds of planning reach 90 % of the final log D-opt.

    python bench/planner_vs_random.py [--seeds 20] [--budget 30] [--time 30] [--process-noise]
        [--rotor-headroom F] [--controller-model {truth,prior}]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from mavsysid.estimation.filter.estimator import EstimatorSettings, estimate_parameters
from mavsysid.estimation.readers import load_flight
from mavsysid.experiments.evaluation_intervals import OFF_PATH_RMS, SATURATED_SHARE
from mavsysid.experiments.experiment import CONTROLLER_MODELS, controller_config
from mavsysid.flight.offline.effects import ProcessNoise
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.planner.baseline import plan_random
from mavsysid.planner.belief import propagate_final
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.rrbt import plan
from mavsysid.planner.search_setup import initial_covariance
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from mavsysid.vehicle.linearization import ErrorStateModel
from scipy.stats import bootstrap


def fly_and_estimate(truth: VehicleConfig, prior: VehicleConfig, result: PlanResult,
                     directory: Path, seed: int, process_noise: bool = False,
                     controller_model: str = "truth"):
    """Fly the plan with the true θ and filter the log.

    The flight controller is tuned to the truth (the paper's RotorS controller; a tuned
    autopilot) or, with ``controller_model="prior"``, to the planner's ±50 % guess. With
    ``process_noise`` the world carries the force and moment noise the filter assumes, so
    that its σ can be compared with the spread of its errors.
    """
    effects = [ProcessNoise(prior.noise.force_density, prior.noise.moment_density,
                            seed=seed)] if process_noise else []
    controlled = controller_config(controller_model, truth, prior)
    sim = Simulator(controlled, true_theta=truth.theta, settings=SimulationSettings(seed=seed),
                    effects=effects).run(result.trajectory, directory)
    flight = load_flight(directory / "pose.csv", prior)
    return sim, estimate_parameters(flight, prior, EstimatorSettings(refine=False))


def flown_sigma(truth: VehicleConfig, settings: PlannerSettings, sim) -> np.ndarray:
    """σ the planner's belief propagation predicts with the true θ along the flown states."""
    model = ErrorStateModel.for_vehicle(truth)
    sigma = propagate_final(model, initial_covariance(model, truth, settings), sim.states,
                            sim.rotor_speeds, truth.theta, float(sim.times[1] - sim.times[0]))
    return np.sqrt(np.diag(model.parameter_covariance_si(sigma)))


def median_interval(samples: tuple[np.ndarray, ...], statistic) -> tuple[float, float]:
    """95 % percentile bootstrap interval over seeds (samples resampled in pairs)."""
    if samples[0].size < 2:
        return float("nan"), float("nan")
    result = bootstrap(samples, statistic, paired=True, vectorized=False,
                       n_resamples=2000, method="percentile", rng=np.random.default_rng(0))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def time_to_90(result: PlanResult) -> float:
    """Planning seconds until the best log D-opt is within 10 % of the final (log scale)."""
    h = result.stats.best_history
    final = np.log(h[-1, 1])
    first = np.log(h[0, 1])
    target = final + 0.1 * (first - final)
    return float(h[np.argmax(np.log(h[:, 1]) <= target), 0])


def parse_args() -> argparse.Namespace:
    """The benchmark's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--budget", type=float, default=30.0)
    parser.add_argument("--time", type=float, default=30.0)
    parser.add_argument("--vehicle", default="firefly")
    parser.add_argument("--rotor-headroom", type=float, default=PlannerSettings.rotor_headroom,
                        help="planner's rotor headroom (fraction of the n² range at each end)")
    parser.add_argument("--controller-model", choices=CONTROLLER_MODELS, default="truth",
                        help="θ the flight controller is tuned with (default: truth)")
    parser.add_argument("--process-noise", action="store_true",
                        help="fly in a world with the process noise the filter assumes")
    return parser.parse_args()


def fly_seeds(args: argparse.Namespace, truth: VehicleConfig) -> list[dict]:
    """Plan (D-optimal and random), fly and estimate for each seed; one row per seed."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            rng = np.random.default_rng(20_000 + seed)
            prior = truth.with_parameters(truth.theta * (1.0 + rng.uniform(-0.5, 0.5, 6)))
            settings = PlannerSettings(budget=args.budget, planning_time=args.time, seed=seed,
                                       rotor_headroom=args.rotor_headroom)
            row = {"prior": prior.theta}
            for kind, planner in (("dopt", plan), ("random", plan_random)):
                result = planner(prior, settings)
                sim, est = fly_and_estimate(truth, prior, result, Path(tmp) / f"{kind}-{seed}",
                                            seed, args.process_noise,
                                            args.controller_model)
                row[kind] = (result, est, sim)
            rows.append(row)
            (p, e, ps), (rp, re, rs) = row["dopt"], row["random"]
            print(f"seed {seed:2d}: dopt predicted {p.predicted_dopt:.3g} reached "
                  f"{e.filtered.d_optimality:.3g} | random predicted {rp.predicted_dopt:.3g} "
                  f"reached {re.filtered.d_optimality:.3g} | vertices {p.stats.vertices}, "
                  f"edges {p.stats.edges}, beliefs {p.stats.beliefs} | saturated "
                  f"{ps.saturated_fraction:.0%}/{rs.saturated_fraction:.0%}, tracking RMS "
                  f"{ps.position_rms:.2g}/{rs.position_rms:.2g} m", flush=True)
    return rows


def report_flights(args: argparse.Namespace, rows: list[dict]) -> None:
    """Saturated and off-path flights, and the reached D-opt of both planners."""
    kinds = ("dopt", "random")
    reached = {k: np.array([r[k][1].filtered.d_optimality for r in rows]) for k in kinds}
    predicted = {k: np.array([r[k][0].predicted_dopt for r in rows]) for k in kinds}
    print(f"\n{args.seeds} seeds, budget {args.budget:g} s, planning {args.time:g} s, "
          f"{args.vehicle}, priors ±50 %, rotor headroom {args.rotor_headroom:g}, controller "
          f"tuned to the {args.controller_model}")
    for k in kinds:
        sims = [r[k][2] for r in rows]
        print(f"  {k:<7} flights saturating > {100 * SATURATED_SHARE:g} % of ticks: "
              f"{sum(s.saturated_fraction > SATURATED_SHARE for s in sims)}, tracking RMS > "
              f"{OFF_PATH_RMS:g} m: {sum(s.position_rms > OFF_PATH_RMS for s in sims)} (true θ "
              "beyond the plan's rotor range)")
    for k in kinds:
        print(f"  {k:<7} median D-opt predicted {np.median(predicted[k]):.3g}, reached by the "
              f"estimator {np.median(reached[k]):.3g}")
    lo, hi = median_interval((reached["random"], reached["dopt"]),
                             lambda a, b: np.median(a) / np.median(b))
    print(f"  ratio random/dopt of median reached D-opt: "
          f"{np.median(reached['random']) / np.median(reached['dopt']):.2f} (paper: 4.4; "
          f"95 % paired bootstrap interval over seeds {lo:.2f}–{hi:.2f})")


def report_sigma(truth: VehicleConfig, rows: list[dict]) -> None:
    """The planner's predicted σ against the estimator's, and the estimator's calibration."""
    sig_pred = np.array([r["dopt"][0].predicted_sigma[-1] for r in rows])
    sig_est = np.array([r["dopt"][1].filtered.sigma for r in rows])
    ratio = sig_pred / sig_est
    print("  predicted/estimator final σ (dopt plans), median (95 % bootstrap interval of "
          "the median) [min, max] per parameter:")
    for j, name in enumerate(PARAMETER_NAMES):
        lo, hi = median_interval((ratio[:, j],), np.median)
        print(f"    {name}: {np.median(ratio[:, j]):.2f} ({lo:.2f}–{hi:.2f}) "
              f"[{ratio[:, j].min():.2f}, {ratio[:, j].max():.2f}]")
    relative = ratio * np.array([r["dopt"][1].filtered.value for r in rows]) / np.array(
        [r["prior"] for r in rows])
    print("  the same in relative σ (σ / θ of the model each used: the planner's prior, the "
          "estimate): " + ", ".join(f"{n} {np.median(relative[:, j]):.2f}"
                                    for j, n in enumerate(PARAMETER_NAMES)))
    calm = np.array([r["dopt"][2].saturated_fraction <= SATURATED_SHARE for r in rows])
    if calm.any():
        print(f"  the same on the {calm.sum()} dopt flights saturating ≤ "
              f"{100 * SATURATED_SHARE:g} % of ticks: "
              + ", ".join(f"{n} {np.median(ratio[calm, j]):.2f}"
                          for j, n in enumerate(PARAMETER_NAMES)))
    flown = sig_est / np.array([flown_sigma(truth, r["dopt"][0].settings, r["dopt"][2])
                                for r in rows])
    print("  estimator σ / σ propagated with the true θ along the flown states, median [min, "
          "max]: " + ", ".join(f"{n} {np.median(flown[:, j]):.2f} [{flown[:, j].min():.2f}, "
                               f"{flown[:, j].max():.2f}]" for j, n in enumerate(PARAMETER_NAMES)))
    errors = np.array([(r["dopt"][1].filtered.value - truth.theta) / r["dopt"][1].filtered.sigma
                       for r in rows])
    print(f"  estimator error / σ over seeds (dopt): std per parameter "
          f"{np.round(errors.std(axis=0), 2).tolist()} (1 if σ matches the spread)")


def report_planner(rows: list[dict]) -> None:
    """Planning time to a good plan, search speed and refinement."""
    t90 = [time_to_90(r["dopt"][0]) for r in rows]
    first = [r["dopt"][0].stats.time_to_first_solution for r in rows]
    st = rows[0]["dopt"][0].stats
    print(f"  planning time to 90 % of the final log D-opt: median {np.median(t90):.1f} s; "
          f"first feasible solution: median {np.median(first):.2f} s")
    print(f"  speed (seed 0): {st.edges_attempted / st.elapsed:.0f} edges tried/s, "
          f"{st.edges / st.edge_time:.0f} feasible edges built per s of edge time, "
          f"{st.beliefs_propagated / max(st.propagation_time, 1e-9):.0f} beliefs propagated/s")
    steps = np.array([r["dopt"][0].stats.refine_steps for r in rows])
    kept = np.array([r["dopt"][0].stats.refine_accepted for r in rows])
    print(f"  refinement: median {np.median(steps):.0f} steps per plan, {np.median(kept):.0f} kept")


def main() -> None:
    args = parse_args()
    truth = load_vehicle(args.vehicle)
    rows = fly_seeds(args, truth)
    report_flights(args, rows)
    report_sigma(truth, rows)
    report_planner(rows)


if __name__ == "__main__":
    main()
