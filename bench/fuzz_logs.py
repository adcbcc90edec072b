"""Fuzzed flight logs of every format through the estimator (issue 19's acceptance).

Simulates a few short clean Firefly flights, writes each as every format the estimator
reads (pose.csv, .tlog, .ulg, .bin), estimates each clean log, then ``--count`` fuzzed
logs (`tests.support.log_fuzz`: mutated values — ±1e30, NaN/inf, negative or absurd
rotor speeds, stretched/reversed/duplicated clocks, stuck signals, wrong units — and
mutated bytes — truncation, flipped bytes, junk, empty and huge files). Each log runs in
a worker process through `mavsysid.pipeline.estimate.run_estimate` (what
``mavsysid estimate`` calls) with a wall-time limit (``--hang``) that counts a hang.

Prints: total, refusals by error type, exit 0, tracebacks, hangs, the largest wall time
per log, the worst θ error among exit-0 results, and the violations: exit 0 with a
parameter more than 50 % off on a log whose clean version estimates within 1 %.

    nice python bench/fuzz_logs.py [--count 1000] [--seed 19] [--flights 3]
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

from tests.support.fuzz_run import Outcome, estimate_outcome, fuzz_plan
from tests.support.log_fuzz import FORMATS, CleanFlight, clean_flight, fuzz_case

_VEHICLE = "firefly"
_HUGE = 3 * 1024**3  # bytes of the sparse "huge" file, above the readers' bound


def _worker_case(args: tuple) -> tuple[str, Outcome]:
    root, clean, suffix, value, byte, seed, index = args
    case = fuzz_case(Path(root) / f"case{index}", clean, suffix, value, byte, seed, _HUGE)
    outcome = estimate_outcome(case.path, _VEHICLE, load_vehicle(_VEHICLE).theta)
    for child in case.path.parent.iterdir():
        child.unlink()
    case.path.parent.rmdir()
    return f"{suffix} {value}/{byte} seed {seed}", outcome


def _run_all(jobs: list[tuple], hang: float, processes: int) -> list[tuple[str, Outcome]]:
    """Each job in a worker; a job over ``hang`` s is a hang (its pool is replaced)."""
    results: list[tuple[str, Outcome]] = []
    pool = multiprocessing.Pool(processes, maxtasksperchild=200)
    futures = {i: pool.apply_async(_worker_case, (job,)) for i, job in enumerate(jobs)}
    for i, job in enumerate(jobs):
        try:
            results.append(futures[i].get(timeout=hang))
        except multiprocessing.TimeoutError:
            label = f"{job[2]} {job[3]}/{job[4]} seed {job[5]}"
            results.append((label, Outcome("hang", np.nan, hang, "no answer")))
            pool.terminate()
            pool = multiprocessing.Pool(processes, maxtasksperchild=200)
            futures.update({j: pool.apply_async(_worker_case, (jobs[j],))
                            for j in range(i + 1, len(jobs))})
        if len(results) % 100 == 0:
            print(f"  {len(results)} of {len(jobs)} logs", file=sys.stderr, flush=True)
    pool.close()
    pool.join()
    return results


def _report(results: list[tuple[str, Outcome]], clean_ok: dict[str, bool]) -> None:
    kinds = collections.Counter(o.kind for _, o in results)
    print(f"total {len(results)} fuzzed logs")
    for kind, count in sorted(kinds.items()):
        print(f"  {kind:16s} {count}")
    longest = max(results, key=lambda r: r[1].seconds)
    print(f"max wall time per log: {longest[1].seconds:.2f} s ({longest[0]})")
    exit0 = [(label, o) for label, o in results if o.kind == "exit0"]
    if exit0:
        worst = max(exit0, key=lambda r: r[1].error)
        print(f"worst θ error among exit 0: {100 * worst[1].error:.3g} % ({worst[0]})")
    kinds_by_mutation = collections.Counter(
        (label.split()[1].split("/")[0], o.kind) for label, o in results)
    print("by value mutation: " + ", ".join(f"{m} {k} {c}" for (m, k), c
                                            in sorted(kinds_by_mutation.items())))
    for label, o in sorted(exit0, key=lambda r: -r[1].error)[:10]:
        print(f"  exit 0, {100 * o.error:.3g} % off: {label}")
    bad = [(label, o) for label, o in exit0
           if o.error > 0.5 and clean_ok[label.split()[0]]]
    print(f"exit 0 with a parameter > 50 % off (clean log within 1 %): {len(bad)}")
    for label, o in bad + [(lb, o) for lb, o in results if o.kind in ("traceback", "hang")]:
        print(f"  {o.kind} {label}: {o.error:.3g} {(o.message + ' ').splitlines()[0][:300]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=19)
    parser.add_argument("--flights", type=int, default=3, help="clean flights (seeds)")
    parser.add_argument("--hang", type=float, default=180.0, help="s per log counted a hang")
    parser.add_argument("--processes", type=int, default=1)
    args = parser.parse_args()
    vehicle = load_vehicle(_VEHICLE)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        flights: list[CleanFlight] = [clean_flight(vehicle, root / f"sim{s}", seed=s)
                                      for s in range(args.flights)]
        clean_ok: dict[str, bool] = {}
        for suffix in FORMATS:
            errors = [estimate_outcome(fuzz_case(root / f"clean{s}", f, suffix, "none", "none",
                                                 0).path, _VEHICLE, vehicle.theta)
                      for s, f in enumerate(flights)]
            clean_ok[suffix] = all(o.kind == "exit0" and o.error < 0.01 for o in errors)
            shown = ", ".join(f"{100 * o.error:.2f} %" if o.kind == "exit0" else o.kind
                              for o in errors)
            print(f"clean {suffix}: {shown} (within 1 %: {clean_ok[suffix]})")
        plan = fuzz_plan(args.count, args.seed)
        jobs = [(str(root), flights[i % len(flights)], *case, i)
                for i, case in enumerate(plan)]
        start = time.perf_counter()
        results = _run_all(jobs, args.hang, args.processes)
        print(f"wall time {time.perf_counter() - start:.0f} s")
    _report(results, clean_ok)


if __name__ == "__main__":
    main()
