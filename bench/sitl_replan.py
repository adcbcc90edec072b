"""Re-planning in flight on a real ArduCopter (SITL, ../shared/sitl, loopback only).

Plans a 6 s opening for the SITL quad (tests/data/sitl_quad_x.toml; its nominal θ is the
prior) at the highest rotor confidence of 1, 0.5, 0 that admits one, then streams it with
``--set-limits --replan-budget 16``: the continuation estimates θ from the opening and
plans the rest. Prints the plan attempts and the stream's output.

    python bench/sitl_replan.py [WORKDIR]
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.sitl import running_sitl  # noqa: E402

DATA = ROOT / "tests" / "data"
VEHICLE = str(DATA / "sitl_quad_x.toml")


def mavsysid(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess:
    """Run the CLI, capturing its output."""
    return subprocess.run([sys.executable, "-m", "mavsysid", *args], capture_output=True,
                          text=True, timeout=timeout, check=False)


def main() -> None:
    work = Path(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="sitl-replan-"))
    (work / "sitl").mkdir(parents=True, exist_ok=True)
    opening = work / "opening.json"
    for z in ("1", "0.5", "0"):
        plan = mavsysid("plan", "--vehicle", VEHICLE, "--budget", "6", "--samples", "300",
                        "--time", "0", "--refine-steps", "300", "--seed", "1",
                        "--rotor-confidence", z, "--rotor-headroom", "0.1",
                        "--autopilot-limits", str(DATA / "sitl_quad_calibration.parm"),
                        "-o", str(opening))
        print(f"opening at z = {z}: exit {plan.returncode} {plan.stderr.strip()}", flush=True)
        if plan.returncode == 0:
            break
    else:
        return
    with running_sitl(work / "sitl", defaults=[DATA / "sitl_quad_x_stock.parm"]) as sitl:
        began = time.time()
        stream = mavsysid("stream", str(opening), "--connect", sitl.connect, "--vehicle", VEHICLE,
                          "--set-limits", "--log-dir", str(work / "logs"), "--replan-budget", "16",
                          "--replan-samples", "300", "--replan-refine-steps", "300")
        print(f"stream: exit {stream.returncode} after {time.time() - began:.0f} s", flush=True)
        print(stream.stdout + stream.stderr)


if __name__ == "__main__":
    main()
