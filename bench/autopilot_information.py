"""What each flight is predicted to determine, per parameter, once the autopilot flies it.

The SITL quad (`sitl_quad`, its reference θ as the planner's model, prior σ 50 %) with
ArduCopter SITL's parameters (`bench/sitl_loop.parm`: its limits, as `plan
--autopilot-limits` reads them, and its loop, `mavsysid.vehicle.autopilot_loop`), per seed:

* ``exact``: the planner as in the paper (the setpoints flown exactly);
* ``model``: the planner on the flight the autopilot is predicted to fly
  (`PlannerSettings.autopilot`);
* ``practitioner``: the built-in Lissajous with yaw scaled to the same limits and budget
  (`mavsysid.experiments.baselines.practitioner_excitation`).

Each flight's belief is propagated (the planner's own recursion at the measurement rate,
`mavsysid.experiments.data_efficiency.belief_history`) along the flight the autopilot is
predicted to fly, and, for reference, along its setpoints. Reported: σ/θ per parameter,
D-opt det(Σθ)^(1/6) (SI) and the planning time (wall, sample-budgeted search).

    nice python bench/autopilot_information.py [--seeds 1 2 3] [--budget 20]
        [--samples 200] [--refine-steps 300] [--time T] [--json OUT]
    python bench/autopilot_information.py --timing [--seeds 1 2 3]
    python bench/autopilot_information.py --save-loop DATAFLASH.BIN OUT.parm
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

VEHICLE = "sitl_quad"
LOOP_FILE = REPO / "bench" / "sitl_loop.parm"
KINDS = ("exact", "model", "practitioner")


def sitl_setup():
    """(vehicle, limits, loop) of ArduCopter SITL as `bench/sitl_loop.parm` holds them."""
    from mavsysid.flight.autopilot_modes import Autopilot
    from mavsysid.flight.ground.autopilot_limits import kinematic_limits
    from mavsysid.formats.parameter_file import read_parameter_file
    from mavsysid.vehicle.autopilot_loop import AutopilotLoop
    from mavsysid.vehicle.config import load_vehicle

    values = read_parameter_file(LOOP_FILE)
    return (load_vehicle(VEHICLE), kinematic_limits(Autopilot.ARDUPILOT, values),
            AutopilotLoop.from_parameters("ardupilot", values))


def flights(seed: int, args: argparse.Namespace) -> dict:
    """Each kind's trajectory and planning time for one seed."""
    from mavsysid.experiments.baselines import practitioner_excitation
    from mavsysid.planner.rrbt import plan
    from mavsysid.planner.settings import PlannerSettings

    config, limits, loop = sitl_setup()
    settings = PlannerSettings(budget=args.budget, seed=seed, autopilot_limits=limits,
                               planning_time=args.time if args.time else np.inf,
                               max_samples=None if args.time else args.samples,
                               refine_steps=args.refine_steps)
    out = {}
    for kind, autopilot in (("exact", None), ("model", loop)):
        began = time.perf_counter()
        result = plan(config, replace(settings, autopilot=autopilot))
        out[kind] = (result.trajectory, time.perf_counter() - began, result.stats.samples,
                     result.stats.refine_steps)
    out["practitioner"] = (practitioner_excitation(config, settings).trajectory, 0.0, 0, 0)
    return out


def information(trajectory, autopilot) -> tuple[np.ndarray, float]:
    """σ/θ per parameter and D-opt (SI) after ``trajectory``, flown by ``autopilot``
    (None: exactly)."""
    from mavsysid.experiments.data_efficiency import belief_history
    from mavsysid.planner.settings import PlannerSettings

    config, _, _ = sitl_setup()
    history = belief_history(config, trajectory, PlannerSettings(autopilot=autopilot))
    return history.sigma[-1] / config.theta, float(history.dopt[-1])


def run(args: argparse.Namespace) -> list[dict]:
    """One row per seed and kind: planning time, and σ/θ, D-opt flown by the autopilot
    (``model``) and exactly (``setpoints``)."""
    _, _, loop = sitl_setup()
    rows = []
    for seed in args.seeds:
        for kind, (trajectory, seconds, samples, steps) in flights(seed, args).items():
            flown, flown_dopt = information(trajectory, loop)
            exact, exact_dopt = information(trajectory, None)
            rows.append({"seed": seed, "kind": kind, "plan_s": seconds, "samples": samples,
                         "refine_steps": steps, "duration": trajectory.duration,
                         "model": {"rel_sigma": flown.tolist(), "dopt": flown_dopt},
                         "setpoints": {"rel_sigma": exact.tolist(), "dopt": exact_dopt}})
            print_row(rows[-1])
    return rows


def print_row(row: dict) -> None:
    """One line: kind, seed, plan time, D-opt and σ/θ (%) predicted on the flown flight."""
    from mavsysid.vehicle.config import PARAMETER_NAMES

    m, s = row["model"], row["setpoints"]
    cells = "  ".join(f"{n} {100 * v:6.2f}" for n, v in zip(PARAMETER_NAMES, m["rel_sigma"],
                                                             strict=True))
    print(f"{row['kind']:12s} seed {row['seed']}  plan {row['plan_s']:5.1f} s "
          f"({row['samples']} samples, {row['refine_steps']} steps)  "
          f"{row['duration']:5.2f} s  D-opt flown {m['dopt']:.3g} (as set {s['dopt']:.3g})  "
          f"σ/θ % flown: {cells}", flush=True)


def summary(rows: list[dict]) -> None:
    """Per kind: median D-opt flown, its ratio to the model plan's, median σ/θ."""
    from mavsysid.vehicle.config import PARAMETER_NAMES

    by = {k: [r for r in rows if r["kind"] == k] for k in KINDS}
    base = {r["seed"]: r["model"]["dopt"] for r in by["model"]}
    print(f"{'kind':12s} {'D-opt':>9s} {'÷ model':>8s} {'plan s':>7s} {'samples':>7s}  "
          "median σ/θ % (flown)")
    for kind, items in by.items():
        dopt = np.median([r["model"]["dopt"] for r in items])
        ratio = np.median([r["model"]["dopt"] / base[r["seed"]] for r in items])
        sig = np.median([r["model"]["rel_sigma"] for r in items], axis=0)
        plan_s = np.median([r["plan_s"] for r in items])
        samples = np.median([r["samples"] for r in items])
        print(f"{kind:12s} {dopt:9.3g} {ratio:8.2f} {plan_s:7.1f} {samples:7.0f}  " + "  ".join(
            f"{n} {100 * v:.2f}" for n, v in zip(PARAMETER_NAMES, sig, strict=True)))


def timing(seeds: list[int]) -> None:
    """CPU and wall time of sample-budgeted plans (200 samples, 300 steps), exact and on
    the model, one after the other after a warm-up that loads the kernels."""
    from mavsysid.planner.rrbt import plan
    from mavsysid.planner.settings import PlannerSettings

    config, limits, loop = sitl_setup()
    base = PlannerSettings(budget=20.0, planning_time=np.inf, max_samples=30, refine_steps=20,
                           seed=9, autopilot_limits=limits)
    plan(config, base)
    plan(config, replace(base, autopilot=loop))
    for seed in seeds:
        for name, autopilot in (("exact", None), ("model", loop)):
            settings = replace(base, max_samples=200, refine_steps=300, seed=seed,
                               autopilot=autopilot)
            wall, cpu = time.perf_counter(), time.process_time()
            result = plan(config, settings)
            print(f"{name:6s} seed {seed}: wall {time.perf_counter() - wall:.2f} s, CPU "
                  f"{time.process_time() - cpu:.2f} s, {result.stats.edges} edges",
                  flush=True)


def save_loop(dataflash: Path, out: Path) -> None:
    """The loop and limit parameters of a DataFlash log's PARM messages, as a .parm file."""
    from mavsysid.flight.autopilot_modes import Autopilot
    from mavsysid.flight.ground.autopilot_limits import parameter_names
    from mavsysid.vehicle.autopilot_loop import loop_parameter_names

    from bench.autopilot_prediction import dataflash_parameters

    values = dataflash_parameters(dataflash)
    names = sorted(set(loop_parameter_names("ardupilot"))
                   | set(parameter_names(Autopilot.ARDUPILOT)))
    head = LOOP_FILE.read_text().splitlines()[:6] if LOOP_FILE.exists() else []
    body = [f"{n} {values[n]:.7g}" for n in names if n in values]
    out.write_text("\n".join([line for line in head if line.startswith("#")] + body) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--budget", type=float, default=20.0)
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--refine-steps", type=int, default=300)
    parser.add_argument("--time", type=float, help="plan for this wall time instead, s")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--save-loop", nargs=2, type=Path, metavar=("DATAFLASH", "OUT"))
    parser.add_argument("--timing", action="store_true",
                        help="only time sample-budgeted plans, exact and on the model")
    args = parser.parse_args()
    if args.timing:
        timing(args.seeds)
        return
    if args.save_loop:
        save_loop(*args.save_loop)
        return
    rows = run(args)
    summary(rows)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
