"""Re-planning in flight on a real ArduCopter (SITL, ../shared/sitl, loopback only).

Per seed: plans a 6 s opening for the SITL quad (``--vehicle sitl_quad``; its reference θ
is the prior) at the highest rotor confidence of 1, 0.5, 0 that admits one, then streams
it to a fresh SITL flown as that vehicle (``--model x``, ``copter.parm`` +
``vehicle/configs/sitl_quad.parm``: X frame, rotor speeds from the motor outputs) with
``--set-limits --replan-budget 16``: the continuation estimates θ from the opening and
plans the rest. Prints the plan attempts, the stream's exit code and its output.

    python bench/sitl_replan.py [--seeds 1 2 3] [--work DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.sitl import running_sitl  # noqa: E402

DATA = ROOT / "tests" / "data"
VEHICLE = "sitl_quad"
SITL_PARMS = ROOT / "vehicle" / "configs" / "sitl_quad.parm"


def mavsysid(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess:
    """Run the CLI, capturing its output."""
    return subprocess.run([sys.executable, "-m", "mavsysid", *args], capture_output=True,
                          text=True, timeout=timeout, check=False)


def replan_seed(work: Path, seed: int) -> None:
    """Plan the opening for ``seed`` and stream it with re-planning to a fresh SITL."""
    work.mkdir(parents=True, exist_ok=True)
    opening = work / "opening.json"
    for z in ("1", "0.5", "0"):
        plan = mavsysid("plan", "--vehicle", VEHICLE, "--budget", "6", "--samples", "300",
                        "--time", "0", "--refine-steps", "300", "--seed", str(seed),
                        "--rotor-confidence", z, "--rotor-headroom", "0.1",
                        "--autopilot-limits", str(DATA / "sitl_quad_calibration.parm"),
                        "-o", str(opening))
        last = (plan.stderr.strip().splitlines() or [""])[-1]
        print(f"seed {seed}: opening at z = {z}: exit {plan.returncode} {last}", flush=True)
        if plan.returncode == 0:
            break
    else:
        return
    with running_sitl(work / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
        began = time.time()
        stream = mavsysid("stream", str(opening), "--connect", sitl.connect, "--vehicle",
                          VEHICLE, "--set-limits", "--log-dir", str(work / "logs"),
                          "--replan-budget", "16", "--replan-samples", "300",
                          "--replan-refine-steps", "300", "--replan-seed", str(seed))
    print(f"seed {seed}: stream exit {stream.returncode} after {time.time() - began:.0f} s",
          flush=True)
    (work / "stream.out").write_text(stream.stdout + stream.stderr)
    print(stream.stdout + stream.stderr, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--work", type=Path, help="keep the flights here")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="sitl-replan-"))
    for seed in args.seeds:
        replan_seed(work / f"seed{seed}", seed)
    print(f"flights in {work}")


if __name__ == "__main__":
    main()
