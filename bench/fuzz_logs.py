"""Fuzzed flight logs of every format through the estimator.

Simulates a few short clean Firefly flights (with the simulator's IMU), writes each as
every format the estimator reads (pose.csv with its IMU columns, .tlog with RAW_IMU or
HIGHRES_IMU, .ulg with sensor_combined, .bin with IMU or GYR/ACC), estimates each clean
log, then ``--count`` fuzzed logs (`tests.support.log_fuzz`): a share ``--imu-share`` of
the IMU's value mutations alone, every (format, IMU mutation) pair in turn
(`tests.support.fuzz_run.imu_plan`: bad cells, drop-outs, a stuck sensor, deg/s, g,
flipped or swapped axes, FRD read as FLU, offset, reversed, jittered or jumping IMU
clocks, another rate, duplicated rows, partial coverage, no IMU), the rest the seeded mix
of `tests.support.fuzz_run.fuzz_plan` (mutated values of every stream — ±1e30, NaN/inf,
negative or absurd rotor speeds, stretched/reversed/duplicated clocks, stuck signals,
wrong units, the IMU's — and mutated bytes — truncation, flipped bytes, junk, empty and
huge files). Each log runs in a worker process through
`mavsysid.pipeline.estimate.run_estimate` (what ``mavsysid estimate`` calls) with a
wall-time limit (``--hang``) that counts a hang.

Prints the clean logs' θ error and the truth's largest distance in σ, then per value
mutation and per byte mutation the outcomes: exit 0 right (every parameter within 50 % of
the truth, the truth within 3 σ of every determined parameter), refused in one line (a
documented error, exit 2 or 3), exit 0 and wrong (a parameter more than 50 % off; else
the truth 3–10 σ or more than 10 σ from a determined parameter), a refusal of more than
one line, traceback (exit 1), hang; then every such wrong result (3–10 σ only where the
clean logs are within 3 σ), traceback and hang with its case.

    nice python bench/fuzz_logs.py [--count 1000] [--seed 19] [--flights 3] [--imu-share 0.75]
"""

from __future__ import annotations

import argparse
import collections
import multiprocessing
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.vehicle.config import load_vehicle

from tests.support.fuzz_run import Outcome, estimate_outcome, fuzz_plan, imu_plan
from tests.support.log_fuzz import FORMATS, CleanFlight, clean_flight, fuzz_case

_VEHICLE = "firefly"
_HUGE = 3 * 1024**3  # bytes of the sparse "huge" file, above the readers' bound


def _worker_case(args: tuple) -> Outcome:
    root, clean, suffix, value, byte, seed, index = args
    case = fuzz_case(Path(root) / f"case{index}", clean, suffix, value, byte, seed, _HUGE)
    outcome = estimate_outcome(case.path, _VEHICLE, load_vehicle(_VEHICLE).theta)
    for child in case.path.parent.iterdir():
        child.unlink()
    case.path.parent.rmdir()
    return outcome


def _run_all(jobs: list[tuple], hang: float, processes: int) -> list[Outcome]:
    """Each job in a worker; a job over ``hang`` s is a hang (its pool is replaced)."""
    results: list[Outcome] = []
    pool = multiprocessing.Pool(processes, maxtasksperchild=200)
    futures = {i: pool.apply_async(_worker_case, (job,)) for i, job in enumerate(jobs)}
    for i in range(len(jobs)):
        try:
            results.append(futures[i].get(timeout=hang))
        except multiprocessing.TimeoutError:
            results.append(Outcome("hang", np.nan, hang, "no answer"))
            pool.terminate()
            pool = multiprocessing.Pool(processes, maxtasksperchild=200)
            futures.update({j: pool.apply_async(_worker_case, (jobs[j],))
                            for j in range(i + 1, len(jobs))})
        if len(results) % 100 == 0:
            print(f"  {len(results)} of {len(jobs)} logs", file=sys.stderr, flush=True)
    pool.close()
    pool.join()
    return results


#: Outcome columns, in the order printed.
_COLUMNS = ("right", "refused", ">50 % off", "3–10 σ", ">10 σ", "multi-line", "traceback",
            "hang")


def _column(o: Outcome) -> str:
    """The outcome's column (module docstring)."""
    if o.kind == "exit0":
        if o.error > 0.5:
            return ">50 % off"
        return ">10 σ" if o.sigma_error > 10.0 else "3–10 σ" if o.sigma_error > 3.0 else "right"
    if o.kind in ("traceback", "hang"):
        return o.kind
    return "multi-line" if "\n" in o.message else "refused"


def _table(title: str, rows: dict[str, collections.Counter]) -> None:
    print(f"| {title} | logs | " + " | ".join(_COLUMNS) + " |")
    print("|---" * (len(_COLUMNS) + 2) + "|")
    for name, counts in rows.items():
        print(f"| {name} | {sum(counts.values())} | "
              + " | ".join(str(counts[c]) for c in _COLUMNS) + " |")
    total = sum(rows.values(), collections.Counter())
    print(f"| all | {sum(total.values())} | " + " | ".join(str(total[c]) for c in _COLUMNS)
          + " |\n")


def _report(results: list[tuple[tuple, Outcome]], clean_sigma: float) -> None:
    print(f"total {len(results)} fuzzed logs")
    longest = max(results, key=lambda r: r[1].seconds)
    print(f"max wall time per log: {longest[1].seconds:.2f} s ({_label(longest[0])})\n")
    by_value: dict[str, collections.Counter] = {}
    by_byte: dict[str, collections.Counter] = {}
    by_format: dict[str, collections.Counter] = {}
    for (suffix, value, byte, _), o in results:
        by_value.setdefault(value, collections.Counter())[_column(o)] += 1
        by_format.setdefault(f"{suffix} {value}", collections.Counter())[_column(o)] += 1
        if byte != "none":
            by_byte.setdefault(byte, collections.Counter())[_column(o)] += 1
    _table("value mutation", dict(sorted(by_value.items())))
    _table("byte mutation", dict(sorted(by_byte.items())))
    imu_formats = {k: v for k, v in sorted(by_format.items()) if " imu_" in k}
    print("IMU mutations per format: " + ", ".join(
        f"{k} {sum(v.values())}" + ("" if v["right"] + v["refused"] == sum(v.values())
                                    else " (" + ", ".join(f"{c} {v[c]}" for c in _COLUMNS[2:]
                                                          if v[c]) + ")")
        for k, v in imu_formats.items()) + "\n")
    exit0 = [(case, o) for case, o in results if o.kind == "exit0"]
    if exit0:
        worst = max(exit0, key=lambda r: r[1].error)
        print(f"worst θ error among exit 0: {100 * worst[1].error:.3g} % ({_label(worst[0])})")
        worst = max(exit0, key=lambda r: r[1].sigma_error)
        print(f"largest distance of the truth among determined parameters at exit 0: "
              f"{worst[1].sigma_error:.3g} σ ({_label(worst[0])})")
    quiet = ("right", "refused", "3–10 σ") if clean_sigma > 3.0 else ("right", "refused")
    for case, o in results:
        if _column(o) not in quiet:
            print(f"  {_column(o)} {_label(case)}: {100 * o.error:.3g} %, {o.sigma_error:.3g} σ "
                  f"{(o.message + ' ').splitlines()[0][:300]}")


def _label(case: tuple) -> str:
    suffix, value, byte, seed = case
    return f"{suffix} {value}/{byte} seed {seed}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=19)
    parser.add_argument("--flights", type=int, default=3, help="clean flights (seeds)")
    parser.add_argument("--hang", type=float, default=180.0, help="s per log counted a hang")
    parser.add_argument("--processes", type=int, default=1)
    parser.add_argument("--imu-share", type=float, default=0.75,
                        help="share of the logs with an IMU value mutation alone, each "
                             "(format, mutation) pair in turn")
    args = parser.parse_args()
    vehicle = load_vehicle(_VEHICLE)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        flights: list[CleanFlight] = [clean_flight(vehicle, root / f"sim{s}", seed=s)
                                      for s in range(args.flights)]
        clean_sigma = 0.0
        for suffix in FORMATS:
            outcomes = [estimate_outcome(fuzz_case(root / f"clean{s}", f, suffix, "none",
                                                   "none", 0).path, _VEHICLE, vehicle.theta)
                        for s, f in enumerate(flights)]
            shown = ", ".join(f"{100 * o.error:.2f} % / {o.sigma_error:.2g} σ"
                              if o.kind == "exit0" else o.kind for o in outcomes)
            print(f"clean {suffix}: {shown}")
            clean_sigma = float(np.nanmax([clean_sigma, *(o.sigma_error for o in outcomes)]))
        imu_count = round(args.count * args.imu_share)
        plan = (imu_plan(imu_count, args.seed)
                + fuzz_plan(args.count - imu_count, args.seed))
        jobs = [(str(root), flights[i % len(flights)], *case, i)
                for i, case in enumerate(plan)]
        start = time.perf_counter()
        outcomes = _run_all(jobs, args.hang, args.processes)
        print(f"wall time {time.perf_counter() - start:.0f} s")
    _report(list(zip(plan, outcomes, strict=True)), clean_sigma)


if __name__ == "__main__":
    main()
