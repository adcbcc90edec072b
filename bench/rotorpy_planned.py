"""Planned flight against a hand-designed excitation of the same length, in RotorPy.

An independent simulator flies both (`bench/rotorpy_flights.py`: RotorPy 3.0's Crazyflie
2.0, its own physics — rotor drag linear in the rotor speed, 72 ms motor lag — flown by
its own `SE3Control`, logged at 500 Hz with motion-capture noise and the IMU). Per seed,
the vehicle file is the paper's model with θ drawn ±30 % around RotorPy's reference, as a
new user would write it, and:

* ``planned``: ``mavsysid plan --vehicle vehicle.toml --budget B --box BOX --seed S``
  (the command's defaults: 30 s of planning, 15 % rotor headroom, the file's noise);
* ``practitioner``: the built-in Lissajous with yaw (chirped), B s long, scaled to the
  same vehicle file's limits and box (`mavsysid.experiments.baselines
  .practitioner_excitation`, as the offline baselines and the SITL bench);

each answered by ``mavsysid estimate pose.csv --vehicle vehicle.toml``. Reported per flight:
D-opt det(Σθ)^(1/6) of the estimate's θ block (SI, smaller is better; a parameter not
determined enters at its prior σ), and per parameter the error against RotorPy's
reference, whether its 95 % interval holds it, and its status. c_D's reference is the
hover equivalent of RotorPy's linear law (docs/rotorpy-bench.md).

    nice python bench/rotorpy_planned.py --work DIR [--seeds 0 1 2] [--budget 30] [--jobs 2]
    python bench/rotorpy_planned.py --report DIR
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.rotorpy_flights import (  # noqa: E402
    fly,
    import_rotorpy,
    measured,
    measured_imu,
    params_for,
    reference_theta,
    vehicle_toml,
)
from bench.sitl_practitioner import scored_answer  # noqa: E402

KINDS = ("planned", "practitioner")
#: A Crazyflie arena: 3 × 3 × 1.5 m of flight volume.
BOX = (-1.5, -1.5, 0.3, 1.5, 1.5, 1.8)
PRIOR_ERROR = 0.3


def _trajectory(kind: str, directory: Path, seed: int, budget: float) -> object:
    """The flight of ``kind`` for the vehicle file in ``directory``."""
    from mavsysid.experiments.baselines import practitioner_excitation
    from mavsysid.formats.trajectory_file import read_trajectory
    from mavsysid.planner.settings import PlannerSettings
    from mavsysid.vehicle.config import load_vehicle

    vehicle = directory.parent / "vehicle.toml"
    if kind == "practitioner":
        settings = PlannerSettings(budget=budget, box=BOX)
        return practitioner_excitation(load_vehicle(vehicle), settings).trajectory
    out = directory / "plan.json"
    done = subprocess.run(
        [sys.executable, "-m", "mavsysid", "-q", "plan", "--vehicle", str(vehicle),
         "--budget", f"{budget:g}", "--box", ",".join(f"{x:g}" for x in BOX),
         "--seed", str(seed), "-o", str(out)], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"seed {seed}: plan failed: {done.stderr.strip()}")
    return read_trajectory(out).trajectory


def fly_and_estimate(kind: str, work: Path, seed: int, budget: float) -> dict:
    """Plan or scale, fly in RotorPy, log, estimate; the flight's row."""
    from mavsysid.estimation.report.text import write_estimate_json
    from mavsysid.formats.poselog import PoseLogWriter
    from mavsysid.pipeline.estimate import run_estimate

    from mavsysid.errors import MavsysidError

    rp = import_rotorpy()
    params = params_for(rp["params"], "clean")
    directory = work / f"seed{seed}" / kind
    directory.mkdir(parents=True, exist_ok=True)
    trajectory = _trajectory(kind, directory, seed, budget)
    record = fly(rp, params, "clean", 0.0, trajectory)
    p, q, n = measured(rp, record, "clean", 1000 * seed + KINDS.index(kind))
    gyro, accel = measured_imu(record, 1000 * seed + KINDS.index(kind) + 500)
    log = directory / "pose.csv"
    with PoseLogWriter(log, n.shape[1], overwrite=True, imu=True) as writer:
        writer.write_rows(record.t, p, q, n, gyro=gyro, accel=accel)
    # A tick saturates where a rotor's command was clipped at either limit (as `fly` clips).
    clipped = ((record.commands <= params["rotor_speed_min"])
               | (record.commands >= params["rotor_speed_max"]))
    saturated = float(np.mean(np.any(clipped, axis=1)))
    (directory / "flight.json").write_text(json.dumps(
        {"duration": float(trajectory.duration), "saturated": saturated}))
    try:
        run = run_estimate(log, directory.parent / "vehicle.toml")
    except MavsysidError as error:
        (directory / "refused.txt").write_text(str(error))
        return row(directory)
    write_estimate_json(directory / "estimate.json", run.result, run.config, log)
    return row(directory)


def row(directory: Path) -> dict:
    """D-opt and per-parameter answer of the flight in ``directory`` (refusal: none)."""
    reference = json.loads((directory.parent / "reference.json").read_text())["theta"]
    flight = json.loads((directory / "flight.json").read_text())
    out = {"kind": directory.name, "seed": directory.parent.name, **flight}
    if not (directory / "estimate.json").is_file():
        out["refused"] = (directory / "refused.txt").read_text()
        return out
    answer = json.loads((directory / "estimate.json").read_text())
    return {**out, **scored_answer(answer, np.asarray(reference, dtype=float))}


def prepare(work: Path, seed: int) -> None:
    """The seed's vehicle file (prior drawn ±30 % around the reference) and reference."""
    rp = import_rotorpy()
    params = params_for(rp["params"], "clean")
    reference = reference_theta(params)
    prior = reference * (1.0 + np.random.default_rng(seed).uniform(-PRIOR_ERROR,
                                                                     PRIOR_ERROR, 6))
    directory = work / f"seed{seed}"
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "vehicle.toml").write_text(vehicle_toml(params, prior,
                                                         f"rotorpy_crazyflie_{seed}"))
    (directory / "reference.json").write_text(json.dumps(
        {"theta": reference.tolist(), "prior": prior.tolist()}))


def report(work: Path) -> None:
    """One line per flight, then practitioner / planned D-opt and the error check per seed."""
    from mavsysid.vehicle.config import PARAMETER_NAMES

    rows = {}
    for directory in sorted(work.glob("seed*/*/flight.json")):
        r = row(directory.parent)
        rows[(r["seed"], r["kind"])] = r
    print(f"{'seed':6s} {'kind':12s} {'dur s':>5s} {'sat':>5s} {'D-opt':>9s}  "
          + "  ".join(f"{n:>17s}" for n in PARAMETER_NAMES))
    for (seed, kind), r in sorted(rows.items()):
        if "refused" in r:
            print(f"{seed:6s} {kind:12s} {r['duration']:5.1f} refused: {r['refused']}")
            continue
        cells = [f"{error:+7.2f}% {'in ' if covered else 'OUT'} {(status or '')[:5]:5s}"
                 for error, covered, status in r["params"].values()]
        print(f"{seed:6s} {kind:12s} {r['duration']:5.1f} {100 * r['saturated']:4.1f}% "
              f"{r['dopt']:9.3g}  " + "  ".join(cells))
    for seed in sorted({s for s, _ in rows}):
        planned, practitioner = rows.get((seed, "planned")), rows.get((seed, "practitioner"))
        if not planned or not practitioner or "dopt" not in planned or "dopt" not in practitioner:
            continue
        worse = [n for n in PARAMETER_NAMES
                 if abs(planned["params"][n][0]) > abs(practitioner["params"][n][0])]
        print(f"{seed}: practitioner / planned D-opt {practitioner['dopt'] / planned['dopt']:.2f};"
              f" planned error larger on: {', '.join(worse) or 'none'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path)
    parser.add_argument("--report", type=Path, help="print the table of what DIR holds")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--budget", type=float, default=30.0)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    if args.report:
        report(args.report)
        return
    if args.work is None:
        parser.error("--work DIR or --report DIR")
    for seed in args.seeds:
        prepare(args.work, seed)
    jobs = [(kind, args.work, seed, args.budget) for seed in args.seeds for kind in KINDS]
    with ProcessPoolExecutor(args.jobs) as pool:
        for result in pool.map(fly_and_estimate, *zip(*jobs, strict=True)):
            print(f"{result['seed']} {result['kind']}: D-opt {result.get('dopt', 'refused')}",
                  flush=True)
    report(args.work)


if __name__ == "__main__":
    main()
