"""How much of the budget a plan within an autopilot's limits fills, idle and under load.

Per seed, ``mavsysid plan --vehicle V --budget B --autopilot-limits LIMITS --seed S`` as an
operator runs it (its own process, the default planning time unless ``--time``), with
``--busy`` N busy processes (``python -c 'while True: pass'`` at nice 0, stopped after the
run) or none. Reports the flight against the budget, the predicted D-opt, the planning
wall time, the planner's share of a core (its CPU time over its planning time) and the
machine's 1-minute load average just before the run. Every plan's shortfall note
(`mavsysid.planner.plan_result.shortfall_note`) is shown.

    python bench/planning_fill.py --limits FILE|LINK [--vehicle quad_x] [--budget 20]
        [--seeds 1 2 3] [--busy 0 2] [--time S]
    python bench/planning_fill.py --save-limits LINK OUT.parm

``--save-limits`` reads the position-controller limits from a live vehicle (e.g.
ArduCopter SITL, ``tcp:127.0.0.1:5760``) once and writes them as a parameter dump, so that
the planning runs need no vehicle running beside them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_BUSY = "while True: pass"


def save_limits(link: str, out: Path) -> None:
    """Read the limit parameters from the vehicle on ``link`` and write them as a dump."""
    from mavsysid.flight.ground.vehicle_contact import vehicle_limit_values

    autopilot, values = vehicle_limit_values(link, say=print)
    lines = [f"# {autopilot.name} position-controller limits read from the vehicle on {link}",
             "# by bench/planning_fill.py --save-limits (parameter units)"]
    lines += [f"{name} {value:g}" for name, value in sorted(values.items())]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}: {len(values)} parameters")


def plan_once(args: argparse.Namespace, seed: int, busy: int, directory: Path) -> dict:
    """One ``mavsysid plan`` run with ``busy`` busy processes beside it."""
    out = directory / f"plan_{seed}_{busy}.json"
    command = [sys.executable, "-m", "mavsysid", "-q", "plan", "--vehicle", args.vehicle,
               "--budget", f"{args.budget:g}", "--autopilot-limits", args.limits,
               "--seed", str(seed), "-o", str(out)]
    if args.time is not None:
        command += ["--time", f"{args.time:g}"]
    hogs = [subprocess.Popen([sys.executable, "-c", _BUSY]) for _ in range(busy)]
    try:
        time.sleep(1.0 if busy else 0.0)  # let the busy processes get going
        load = os.getloadavg()[0]
        start = time.perf_counter()
        run = subprocess.run(command, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - start
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    if run.returncode != 0:
        return {"seed": seed, "busy": busy, "load": load, "wall": wall,
                "error": run.stderr.strip()}
    doc = json.loads(out.read_text())
    planner = doc["planner"]
    duration = sum(s["duration"] for s in doc["segments"])
    # .get: a trajectory file of a version without the planner's CPU time and notes
    cpu = planner.get("cpu_time")
    return {"seed": seed, "busy": busy, "load": load, "wall": wall, "duration": duration,
            "fill": duration / args.budget, "dopt": doc["predicted_dopt"],
            "cpu_share": None if cpu is None else cpu / planner["elapsed"],
            "samples": planner["samples"], "search_stop": planner.get("search_stop"),
            "refine_steps": planner["refinement"]["steps"],
            "shortfall": planner.get("shortfall")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limits", help="parameter dump or MAVLink link (plan's "
                        "--autopilot-limits)")
    parser.add_argument("--save-limits", nargs=2, metavar=("LINK", "OUT"))
    parser.add_argument("--vehicle", default="quad_x")
    parser.add_argument("--budget", type=float, default=20.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--busy", type=int, nargs="+", default=[0, 2],
                        help="numbers of busy processes to plan beside (default: 0 2)")
    parser.add_argument("--time", type=float, help="planning time (default: plan's)")
    args = parser.parse_args()
    if args.save_limits is not None:
        save_limits(args.save_limits[0], Path(args.save_limits[1]))
        return
    if args.limits is None:
        parser.error("--limits or --save-limits is required")
    print(f"{args.vehicle}, budget {args.budget:g} s, limits {args.limits}, planning time "
          f"{'default' if args.time is None else f'{args.time:g} s'}; "
          f"{os.cpu_count()} cores", flush=True)
    with tempfile.TemporaryDirectory(prefix="planning-fill-") as tmp:
        for busy in args.busy:
            rows = []
            for seed in args.seeds:
                row = plan_once(args, seed, busy, Path(tmp))
                rows.append(row)
                head = (f"busy {busy} seed {seed}: load {row['load']:.2f}, "
                        f"wall {row['wall']:.1f} s")
                if "error" in row:
                    print(f"{head}: {row['error']}", flush=True)
                    continue
                share = "?" if row["cpu_share"] is None else f"{100 * row['cpu_share']:.0f}"
                print(f"{head}, flight {row['duration']:.2f} s = {100 * row['fill']:.1f} % of "
                      f"the budget, D-opt {row['dopt']:.3g}, core share {share} %, "
                      f"{row['samples']} samples "
                      f"(search: {row['search_stop']}), {row['refine_steps']} refinement "
                      f"steps" + (f"; note: {row['shortfall']}" if row["shortfall"] else ""),
                      flush=True)
            fills = [r["fill"] for r in rows if "fill" in r]
            if fills:
                print(f"busy {busy}: fill min {100 * min(fills):.1f} %, "
                      f"{sum(f >= 0.9 for f in fills)}/{len(rows)} at ≥ 90 %", flush=True)


if __name__ == "__main__":
    main()
