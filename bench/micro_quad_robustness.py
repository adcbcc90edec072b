"""Real-flight robustness on our own data.

For each seed, fly the simulated micro_quad the way real small vehicles are logged
(`tests.support.realistic`: on-board estimator pose lagged 20 ms + 15 ms smoothing with
correlated noise 10× the motion-capture σ; 500 Hz with 0.2 ms stamp jitter, 2 % dropped
samples and three 20–150 ms gaps; hidden motor lag 30 ms, linear rotor drag, 1.2 m/s steady
wind), draw a prior 30–50 % off the truth (seeded, random sign per parameter), run
`run_estimate` and print per parameter the relative error and whether the 95 % interval
covers the truth — or the refusal (exit code and its one line).

Target: every determined θ within 5 % (c_D 15 %) with covering intervals, or an honest
refusal (a parameter the flight does not determine keeps the prior and is not scored).

    nice python bench/micro_quad_robustness.py [--seeds 5] [--duration 60]
        [--no-sensor-path] [--effects motor_lag,rotor_drag_linear,wind]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.pipeline.estimate import run_estimate
from mavsysid.vehicle.config import PARAMETER_NAMES

from mavsysid.cli.main import exit_code
from mavsysid.errors import MavsysidError
from tests.support.realistic import (
    REALISTIC_EFFECTS,
    prior_config,
    realistic_micro_quad_flight,
)

#: Relative error allowed per parameter (c_D: 15 %, the rest 5 %).
TOLERANCE = np.array([0.05, 0.15, 0.05, 0.05, 0.05, 0.05])
#: The issue's acceptance target for this bench (c_T 5 %, c_D 15 %, J 10 %; c_M 5 %),
#: counted beside the stricter `TOLERANCE`.
ISSUE_TARGET = np.array([0.05, 0.15, 0.05, 0.10, 0.10, 0.10])


def _passes(row: dict, tolerance: np.ndarray) -> bool:
    """Every determined parameter within ``tolerance`` and covered by its interval."""
    determined = np.array([s == "determined" for s in row["status"]])
    return bool(np.all(((np.abs(row["error"]) <= tolerance) & row["covered"])[determined]))


def run_seed(seed: int, duration: float, root: Path, sensor_path: bool = True,
             effects: tuple[str, ...] = tuple(REALISTIC_EFFECTS)) -> dict:
    """Fly, estimate and score one seed."""
    t0 = time.perf_counter()
    flight = realistic_micro_quad_flight(root / f"flight-{seed}", seed=seed, duration=duration,
                                         effects=effects, sensor_path=sensor_path)
    simulated = time.perf_counter() - t0
    vehicle, prior = prior_config(flight.config, root / f"prior-{seed}.toml", seed)
    t0 = time.perf_counter()
    try:
        result = run_estimate(flight.pose, vehicle=vehicle).result
        final = result.final.theta
    except MavsysidError as error:
        return {"seed": seed, "code": exit_code(error), "message": str(error),
                "prior": prior / flight.truth - 1.0, "wall": time.perf_counter() - t0,
                "sim": simulated, "rows": flight.rows_kept}
    except Exception as error:  # a bug: what the 0-traceback acceptance forbids
        return {"seed": seed, "code": 1, "message": f"INTERNAL {type(error).__name__}: {error}",
                "prior": prior / flight.truth - 1.0, "wall": time.perf_counter() - t0,
                "sim": simulated, "rows": flight.rows_kept}
    error = final.value / flight.truth - 1.0
    covered = np.abs(final.value - flight.truth) <= 1.96 * final.sigma
    status = result.status[:6] or ("determined",) * len(PARAMETER_NAMES)
    return {"seed": seed, "code": 0, "error": error, "covered": covered, "status": status,
            "sigma": final.sigma / flight.truth, "prior": prior / flight.truth - 1.0,
            "wall": time.perf_counter() - t0, "sim": simulated, "rows": flight.rows_kept}


def _print(row: dict) -> None:
    prior = " ".join(f"{100 * p:+.0f}" for p in row["prior"])
    head = (f"seed {row['seed']:3d}  rows {row['rows']:6d}  sim {row['sim']:5.1f} s  "
            f"estimate {row['wall']:6.1f} s  prior % [{prior}]")
    print(head)
    if row["code"]:
        print(f"    REFUSED exit {row['code']}: {row['message']}")
        return
    determined = np.array([s == "determined" for s in row["status"]])
    ok = (np.abs(row["error"]) <= TOLERANCE) & row["covered"]
    for name, e, s, c, good, d, st in zip(PARAMETER_NAMES, row["error"], row["sigma"],
                                          row["covered"], ok, determined, row["status"],
                                          strict=True):
        verdict = ("ok" if good else "FAIL") if d else f"({st})"
        print(f"    {name:4s} error {100 * e:+8.2f} %  σ {100 * s:6.2f} %  "
              f"95 % covers: {'yes' if c else 'NO '}  {verdict}")
    print(f"    every determined parameter within target and covered: "
          f"{'yes' if ok[determined].all() else 'no'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--no-sensor-path", action="store_true",
                        help="motion-capture pose at exact 500 Hz stamps (to separate causes)")
    parser.add_argument("--effects", default=",".join(REALISTIC_EFFECTS),
                        help="hidden effects, comma-separated (empty: none)")
    args = parser.parse_args()
    effects = tuple(filter(None, args.effects.split(",")))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rows.append(run_seed(seed, args.duration, Path(tmp), not args.no_sensor_path,
                                 effects))
            _print(rows[-1])
            sys.stdout.flush()
    done = [r for r in rows if r["code"] == 0]
    passed = sum(_passes(r, TOLERANCE) for r in done)
    passed_issue = sum(_passes(r, ISSUE_TARGET) for r in done)
    refused = [r for r in rows if r["code"] in (2, 3)]
    internal = [r for r in rows if r["code"] not in (0, 2, 3)]
    print(f"\n{len(rows)} flights: {passed} with every determined parameter within tolerance "
          "and covered, "
          f"{len(done) - passed} confident and wrong (exit 0 outside tolerance or not "
          f"covered), {len(refused)} refused, {len(internal)} internal errors")
    print(f"by the issue's target (c_T, c_M 5 %, c_D 15 %, J 10 %): {passed_issue} of "
          f"{len(rows)} with every determined parameter within it and covered")


if __name__ == "__main__":
    main()
