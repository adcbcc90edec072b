"""Mismatch coverage: does the 95 % interval cover the truth?

Five truths, each hidden from the model, plus the clean flight as a control. For every
truth and seed: fly the Firefly on the built-in 30 s excitation (`tests.support.hidden`,
catalogue physics from `mavsysid.vehicle.model_effects`), read its ``pose.csv`` as
``mavsysid estimate`` reads it (`mavsysid.estimation.readers.load_flight`: the simulator's
IMU columns, gyro and accelerometer with white noise and constant biases at the vehicle
file's σ, become `FlightData.imu`; ``--no-imu`` drops them), draw the prior ±50 % around the
scoring truth (seeded, as `bench/estimate_accuracy.py` does), run
`mavsysid.estimation.filter.estimator.estimate_parameters` (what ``mavsysid estimate`` runs) and
score its final (refined) θ after the checks `mavsysid estimate` applies
(`mavsysid.estimation.check_result`; a refusal counts as not covering).
Prints per truth and parameter the median |relative error| and the share of flights
whose 95 % interval (θ ± 1.96 σ) covers the truth.

Truths (magnitudes of ``bench/diagnose_accuracy.py`` ``CASES``):

* ``motor_lag`` τ = 40 ms, ``wind`` (1.6, 1.2) m/s, ``body_drag`` 5 % of the weight at
  3 m/s, ``pose_delay`` 20 ms: the nominal θ plus the hidden effect; scored against the
  nominal θ.
* ``rotor_drag_linear``: rotor drag linear in rotor speed *instead of* the paper's
  quadratic law, as RotorPy models it. The truth flies with
  c_D = 0 and a hidden ``rotor_drag_linear`` of k = c_T c_D n_h (c_T, c_D nominal; n_h the
  hover rotor speed √(m g / (rotors · c_T))), so both laws give the same drag in hover.
  The estimate is scored against the nominal θ, i.e. c_D's hover equivalent.

``--answer`` scores what ``mavsysid estimate`` prints: its per-parameter answer
(`mavsysid.estimation.estimate`: the force and torque balance checked by the
filter, `mavsysid.estimation.answer`), whose coverage is counted over the
parameters it marks determined (a parameter not determined keeps the prior, which covers
the truth by construction); the table then also gives the share determined.

``--reestimate`` measures θ re-estimated with the named effects (what ``mavsysid estimate
--auto-effects`` runs): `mavsysid.pipeline.auto_effects.estimate_with_named_effects`
estimates θ, lets `mavsysid.discrepancy.diagnosis.diagnose_flight` (from the estimate,
without the NIS) name effects, and estimates θ again with them (fitted jointly); that θ is
scored (the first estimate when nothing is named). When
``rotor_drag_linear`` is among them, c_D is scored as its hover equivalent
c_D + k / (c_T n_h) with σ² = σ_cD² + (σ_k / (c_T n_h))² (their correlation ignored).

At the end: over every truth, the determined parameters, how many of their 95 %
intervals cover the truth, the largest |error|/σ and each miss (truth, seed, parameter,
error, z).

    nice python bench/mismatch_coverage.py [--seeds 20] [--first-seed 0]
        [--truths clean,wind] [--workers 2] [--reestimate | --answer] [--no-imu]
        [--rows rows.jsonl]
    nice python bench/mismatch_coverage.py --from-rows rows.jsonl
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.estimation import check_result, estimate
from mavsysid.estimation.filter.estimator import estimate_parameters
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import Z95, EstimationResult
from mavsysid.pipeline.auto_effects import estimate_with_named_effects
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from mavsysid.vehicle.mav_model import rotor_speed_for_thrust
from mavsysid.vehicle.model_effects import ModelEffect, effect_from_values

from bench.diagnose_accuracy import CASES
from mavsysid.errors import JobFailedError
from tests.support.hidden import hidden_flight

TRUTHS = ("clean", "rotor_drag_linear", "motor_lag", "wind", "body_drag", "pose_delay")
VEHICLE = "firefly"


def truth_side(config: VehicleConfig, truth: str) -> tuple[np.ndarray, list[ModelEffect]]:
    """The θ the truth flies with and its hidden effects (see the module docstring).

    Returns
    -------
    theta : ndarray, shape (6,)
        SI; differs from ``config.theta`` only for ``rotor_drag_linear`` (c_D = 0).
    effects : list of ModelEffect
    """
    theta = config.theta.copy()
    if truth == "clean":
        return theta, []
    if truth != "rotor_drag_linear":
        return theta, [effect_from_values(truth, CASES[truth])]
    theta[1] = 0.0
    k = config.theta[0] * config.theta[1] * hover_speed(config, config.theta[0])
    return theta, [effect_from_values(truth, {"k": k})]


def hover_speed(config: VehicleConfig, c_T: float) -> float:
    """n_h = √(m g / (rotors · c_T)), rad/s."""
    return float(rotor_speed_for_thrust(c_T, config.hover_thrust / config.rotor_count))


def scored(result: EstimationResult, config: VehicleConfig) -> tuple[np.ndarray, np.ndarray]:
    """The final θ and σ (6,), c_D as its hover equivalent if rotor_drag_linear is fitted."""
    final = result.refined if result.refined is not None else result.filtered
    value, sigma = final.value.copy(), np.sqrt(np.diag(final.covariance))
    for fitted in result.effects:
        if fitted.name == "rotor_drag_linear":
            per_k = 1.0 / (value[0] * hover_speed(config, value[0]))
            value[1] += fitted.value[0] * per_k
            sigma[1] = math.hypot(sigma[1], fitted.sigma[0] * per_k)
    return value, sigma


def read_flight(directory: Path, vehicle: VehicleConfig, imu: bool) -> FlightData:
    """The flight's ``pose.csv`` as ``mavsysid estimate`` reads it; without ``imu``, with
    its IMU columns left out."""
    flight = load_flight(directory / "pose.csv", vehicle)
    return flight if imu else replace(flight, imu=None)


def run(truth: str, seed: int, root: str, mode: str = "filter", imu: bool = True
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One flight: (scoring truth, estimate, σ, determined), each shape (6,), SI.

    ``mode``: "filter" (the filter and batch), "reestimate" (with the named effects) or
    "answer" (the per-parameter answer). ``imu``: read the simulator's IMU columns.
    """
    config = load_vehicle(VEHICLE)
    flown, effects = truth_side(config, truth)
    directory = Path(root) / f"{truth}-{seed}"
    hidden_flight(config, directory, effects, seed=seed, true_theta=flown)
    rng = np.random.default_rng(10_000 + seed)
    prior = config.with_parameters(config.theta * (1.0 + rng.uniform(-0.5, 0.5, 6)))
    flight = read_flight(directory, prior, imu)
    everything = np.ones(6, bool)
    try:
        if mode == "answer":
            result = estimate(flight, prior)
            determined = np.array([s == "determined" for s in result.status])
            return config.theta, result.final.theta.value, result.final.theta.sigma, determined[:6]
        result = (estimate_with_named_effects(flight, prior)[0] if mode == "reestimate"
                  else estimate_parameters(flight, prior))
        # what `mavsysid estimate` refuses
        check_result(flight.source, result, prior.limits.rotor_speed_max)
    except JobFailedError:  # refused (exit 3): scored as not covering, error NaN
        return config.theta, np.full(6, np.nan), np.full(6, np.nan), everything
    return (config.theta, *scored(result, prior), everything)


def table(truth: str, rows: list[tuple[np.ndarray, ...]]) -> str:
    """Median |relative error| (%), 95 % coverage (%) and median |error|/σ per parameter,
    over the determined parameters, and the share determined.

    A refused flight (NaN) counts as not covered; medians are over the others.
    """
    reference, value, sigma, determined = (np.array(a) for a in zip(*rows, strict=True))
    error = value - reference
    z = np.abs(error) / sigma
    refused = int(np.sum(np.isnan(value[:, 0])))
    z = np.where(np.isnan(z), np.inf, z)
    answered = ~np.isnan(value[:, 0])
    with np.errstate(invalid="ignore"):
        relative = np.where(determined[answered], np.abs(error / reference)[answered], np.nan)
        stats = (("determined %", 100 * np.mean(determined, 0)),
                 ("median |error| %", 100 * np.nanmedian(relative, 0)),
                 ("95 % covers %", 100 * np.sum((z <= Z95) & determined, 0)
                  / np.maximum(np.sum(determined, 0), 1)),
                 ("median |error|/σ", np.nanmedian(np.where(determined, z, np.nan), 0)))
    lines = [f"\n{truth}: {len(rows)} flights, {refused} refused", f"{'':22}"
             + "  ".join(f"{n:>8}" for n in PARAMETER_NAMES)]
    lines += [f"{label:<22}" + "  ".join(f"{v:>8.3f}" for v in stat) for label, stat in stats]
    return "\n".join(lines)


def misses(results: dict[str, list[tuple[np.ndarray, ...]]], first_seed: int,
           seeds: dict[str, list[int]] | None = None) -> str:
    """Over every truth: determined parameters, how many intervals cover the truth, the
    largest |error|/σ, and each miss (truth, seed, parameter, relative error, z)."""
    count = covered = 0
    worst, lines = 0.0, []
    for truth, rows in results.items():
        for k, (reference, value, sigma, determined) in enumerate(rows):
            for i in np.flatnonzero(determined):
                count += 1
                z = (value[i] - reference[i]) / sigma[i] if np.isfinite(value[i]) else np.inf
                worst = max(worst, abs(z))
                if abs(z) <= Z95:
                    covered += 1
                    continue
                seed = first_seed + k if seeds is None else seeds[truth][k]
                lines.append(f"  {truth} seed {seed} {PARAMETER_NAMES[i]}: "
                             f"{100 * (value[i] / reference[i] - 1):+.3f} % ({z:+.1f} σ)")
    head = (f"\nall truths: {count} determined, {covered} covered by the 95 % interval "
            f"({100 * covered / max(count, 1):.1f} %), largest |error|/σ {worst:.1f}; misses:")
    return "\n".join([head, *lines])


def print_rows(path: Path) -> None:
    """The tables and misses of the rows a ``--rows`` file holds, seeds in file order."""
    results: dict[str, list[tuple[np.ndarray, ...]]] = {}
    seeds: dict[str, list[int]] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        row = json.loads(line)
        results.setdefault(row["truth"], []).append(tuple(np.array(row[k], dtype=float if
            k != "determined" else bool) for k in ("reference", "value", "sigma", "determined")))
        seeds.setdefault(row["truth"], []).append(row["seed"])
    for truth in (t for t in TRUTHS if t in results):
        print(table(truth, results[truth]) + f"\n  seeds {sorted(seeds[truth])}", flush=True)
    print(misses(results, 0, seeds), flush=True)


def _record(path: Path | None, truth: str, seed: int, future: Future) -> None:
    """Append one flight's row (JSON) to ``path`` as it arrives."""
    if path is None or future.exception() is not None:
        return
    reference, value, sigma, determined = future.result()
    row = {"truth": truth, "seed": seed, "reference": reference.tolist(),
           "value": value.tolist(), "sigma": sigma.tolist(),
           "determined": determined.tolist()}
    with path.open("a", encoding="utf-8") as out:
        out.write(json.dumps(row) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--rows", type=Path,
                        help="append each flight's row (JSON lines) here as it arrives")
    parser.add_argument("--no-imu", action="store_true",
                        help="read the flights without their IMU columns")
    parser.add_argument("--truths", default=",".join(TRUTHS),
                        help=f"comma-separated, of {', '.join(TRUTHS)}")
    parser.add_argument("--workers", type=int, default=2)
    modes = parser.add_mutually_exclusive_group()
    modes.add_argument("--reestimate", action="store_true",
                       help="estimate again with the effects a diagnosis names")
    modes.add_argument("--answer", action="store_true",
                       help="score estimate's per-parameter answer (balance and filter)")
    parser.add_argument("--from-rows", type=Path,
                        help="print the tables of a --rows file (of a run cut short) and stop")
    args = parser.parse_args()
    if args.from_rows is not None:
        print_rows(args.from_rows)
        return
    mode = "answer" if args.answer else "reestimate" if args.reestimate else "filter"
    truths = [t for t in args.truths.split(",") if t]
    unknown = sorted(set(truths) - set(TRUTHS))
    if unknown:
        parser.error(f"unknown truth {', '.join(unknown)}; expected some of {', '.join(TRUTHS)}")
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(args.workers) as pool:
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        jobs: dict[str, list[Future]] = {t: [] for t in truths}
        for seed in seeds:  # seed by seed, so that a run cut short covers every truth
            for truth in truths:
                jobs[truth].append(pool.submit(run, truth, seed, tmp, mode, not args.no_imu))
                jobs[truth][-1].add_done_callback(partial(_record, args.rows, truth, seed))
        results = {}
        for truth, futures in jobs.items():
            results[truth] = [f.result() for f in futures]
            print(table(truth, results[truth]), flush=True)
        print(misses(results, args.first_seed), flush=True)


if __name__ == "__main__":
    main()
