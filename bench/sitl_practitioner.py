"""Planned against practitioner's flight on ArduCopter SITL: same limits, box and duration.

Per seed and kind, one fresh SITL (``--model x``, ``vehicle/configs/sitl_quad.parm``, as
`bench/sitl_experiment.py`):

* ``planned``: ``mavsysid experiment --connect … --vehicle sitl_quad --budget B --samples N
  --refine-steps R --seed S`` (plan within the limits read from SITL → fly → estimate).
* ``practitioner``: the limits read from SITL the same way
  (`mavsysid.pipeline.plan.autopilot_limits`), the built-in Lissajous excitation with yaw
  scaled to them and to the vehicle file's limits, B s long, in the same box
  (`mavsysid.experiments.baselines.practitioner_excitation`, the offline baselines'
  generator and check), written as a trajectory file, flown with ``mavsysid stream`` (which
  checks it against the limits again) and estimated with ``mavsysid estimate FLIGHT/
  flight.tlog --vehicle sitl_quad -o estimate.json``.

The practitioner's figure does not depend on the seed; its seeds differ only by the flight.
Reported per flight: duration, D-opt det(Σθ)^(1/6) of ``estimate.json``'s covariance (SI;
smaller is better), and per parameter the error against the SITL reference
(docs/vehicles/sitl_quad.md) with the status ``estimate`` gives it.

    nice python bench/sitl_practitioner.py --kinds planned practitioner --seeds 1 2 3 \\
        --work DIR [--budget 20] [--samples 200] [--refine-steps 300 | --time 30]
        [--noise-from FLIGHT] [--autopilot-model]
    python bench/sitl_practitioner.py --report DIR      # the table of what DIR holds
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.support.sitl import running_sitl  # noqa: E402

SITL_PARMS = REPO / "vehicle" / "configs" / "sitl_quad.parm"
KINDS = ("planned", "practitioner")


def box_text(box) -> str:
    """A box as ``--box`` takes it."""
    return ",".join(f"{v:g}" for v in box)


def fly_planned(connect: str, seed: int, args: argparse.Namespace, logs: Path) -> str:
    """``mavsysid experiment`` on the vehicle at ``connect``; its whole output."""
    from mavsysid.planner.settings import PlannerSettings

    planning = (["--time", f"{args.time:g}"] if args.time else
                ["--samples", str(args.samples), "--refine-steps", str(args.refine_steps)])
    extra = (["--noise-from", *map(str, args.noise_from)] if args.noise_from else []) + (
        ["--autopilot-model"] if args.autopilot_model else [])
    done = subprocess.run(
        [sys.executable, "-m", "mavsysid", "experiment", "--connect", connect,
         "--vehicle", "sitl_quad", "--budget", f"{args.budget:g}", *planning, *extra,
         "--seed", str(seed), "--box", box_text(PlannerSettings.box), "--prearm-timeout",
         "300", "--log-dir", str(logs)], capture_output=True, text=True, check=False)
    return f"exit {done.returncode}\n{done.stdout}{done.stderr}"


def fly_practitioner(connect: str, args: argparse.Namespace, logs: Path) -> str:
    """The practitioner's excitation within the limits read at ``connect``, flown and
    estimated; the commands' output."""
    from mavsysid.experiments.baselines import practitioner_excitation
    from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
    from mavsysid.pipeline.plan import autopilot_limits
    from mavsysid.planner.settings import PlannerSettings
    from mavsysid.vehicle.config import load_vehicle

    config = load_vehicle("sitl_quad")
    source, limits = autopilot_limits(connect, heartbeat_timeout=60.0)
    settings = PlannerSettings(budget=args.budget, autopilot_limits=limits)
    scaled = practitioner_excitation(config, settings)
    logs.mkdir(parents=True, exist_ok=True)
    staged = logs / "practitioner.json"
    write_trajectory_file(staged, trajectory_file_for(scaled.trajectory, config,
                                                      "practitioner", settings.box))
    out = [f"limits: {source}", f"time scale {scaled.scale:.3g}, next faster breaks "
           f"{scaled.binding or 'nothing'}, {scaled.trajectory.duration:.2f} s"]
    flown = subprocess.run(
        [sys.executable, "-m", "mavsysid", "stream", str(staged), "--connect", connect,
         "--vehicle", "sitl_quad", "--box", box_text(settings.box), "--prearm-timeout", "300",
         "--log-dir", str(logs)], capture_output=True, text=True, check=False)
    out.append(f"stream exit {flown.returncode}\n{flown.stdout}{flown.stderr}")
    flights = [p for p in logs.iterdir() if p.is_dir()]
    if flown.returncode == 0 and flights:
        (flights[0] / "trajectory.json").write_bytes(staged.read_bytes())
        estimated = subprocess.run(
            [sys.executable, "-m", "mavsysid", "estimate", str(flights[0] / "flight.tlog"),
             "--vehicle", "sitl_quad", "-o", str(flights[0] / "estimate.json")],
            capture_output=True, text=True, check=False)
        out.append(f"estimate exit {estimated.returncode}\n{estimated.stdout}"
                   f"{estimated.stderr}")
    return "\n".join(out)


def scored_answer(answer: dict, reference: np.ndarray) -> dict:
    """An ``estimate.json`` document scored against the reference θ: ``dopt``, det(Σθ)^(1/6)
    of its θ block (`ParameterEstimate.d_optimality`; NaN where not positive definite), and
    per parameter ``(error %, reference within value ± 1.96 σ, status)``."""
    from mavsysid.estimation import ParameterEstimate
    from mavsysid.vehicle.config import PARAMETER_NAMES

    entries = [answer["parameters"][name] for name in PARAMETER_NAMES]
    six = len(PARAMETER_NAMES)  # θ's block: nuisance quantities follow it
    theta = ParameterEstimate(np.array([e["value"] for e in entries], dtype=float),
                              np.asarray(answer["covariance"], dtype=float)[:six, :six])
    with np.errstate(invalid="ignore", divide="ignore"):
        dopt = theta.d_optimality
    return {"dopt": dopt if np.isfinite(dopt) else float("nan"), "params": {
        name: (100 * (e["value"] / reference[i] - 1),
               bool(abs(e["value"] - reference[i]) <= 1.96 * e["sigma"]), e.get("status"))
        for i, (name, e) in enumerate(zip(PARAMETER_NAMES, entries, strict=True))}}


def flight_row(logs: Path) -> dict | None:
    """Duration, D-opt and per-parameter answer of the flight in ``logs``, or None."""
    from mavsysid.vehicle.config import load_vehicle

    flights = [p for p in logs.iterdir() if p.is_dir()] if logs.is_dir() else []
    if not flights or not (flights[0] / "estimate.json").is_file():
        return None
    answer = json.loads((flights[0] / "estimate.json").read_text())
    return {"duration": json.loads((flights[0] / "trajectory.json").read_text())["duration"],
            **scored_answer(answer, load_vehicle("sitl_quad").theta)}


def report(work: Path) -> None:
    """One line per flight in ``work``: kind, seed, duration, D-opt, errors (%)."""
    from mavsysid.vehicle.config import PARAMETER_NAMES

    print(f"{'kind':12s} {'seed':>4s} {'dur s':>6s} {'D-opt':>9s}  " + "  ".join(
        f"{n:>14s}" for n in PARAMETER_NAMES))
    for kind in KINDS:
        for seed_dir in sorted((work / kind).glob("seed*")):
            row = flight_row(seed_dir / "logs")
            if row is None:
                print(f"{kind:12s} {seed_dir.name[4:]:>4s}  no estimate")
                continue
            cells = [f"{e:+6.1f}{'' if inside else '!'} {str(status)[:6]:>6s}"
                     for e, inside, status in row["params"].values()]
            print(f"{kind:12s} {seed_dir.name[4:]:>4s} {row['duration']:6.2f} "
                  f"{row['dopt']:9.3g}  " + "  ".join(f"{c:>14s}" for c in cells))
    print("errors in % against the SITL reference; ! = reference outside value ± 1.96 σ")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kinds", nargs="+", choices=KINDS, default=list(KINDS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--budget", type=float, default=20.0)
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--refine-steps", type=int, default=300)
    parser.add_argument("--time", type=float,
                        help="plan for this wall time instead of --samples/--refine-steps "
                        "(the planner's default is 30 s)")
    parser.add_argument("--noise-from", type=Path, nargs="+", metavar="FLIGHT",
                        help="planned: plan for the noise the estimator met on FLIGHT "
                        "(`experiment --noise-from`)")
    parser.add_argument("--autopilot-model", action="store_true",
                        help="planned: plan on the flight SITL's loop is predicted to fly")
    parser.add_argument("--work", type=Path, help="where the flights go")
    parser.add_argument("--report", type=Path, help="only tabulate the flights in this folder")
    args = parser.parse_args()
    if args.report:
        report(args.report)
        return
    if args.work is None:
        parser.error("--work DIR is required to fly")
    for seed in args.seeds:
        for kind in args.kinds:
            where = args.work / kind / f"seed{seed}"
            with running_sitl(where / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
                text = (fly_planned(sitl.connect, seed, args, where / "logs")
                        if kind == "planned" else
                        fly_practitioner(sitl.connect, args, where / "logs"))
            (where / "run.out").write_text(text)
            print(f"{kind} seed {seed}: {text.splitlines()[0]}", flush=True)
    report(args.work)


if __name__ == "__main__":
    main()
