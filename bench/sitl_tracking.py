"""Tracking and setpoint rate of a planned quad_x flight on real ArduCopter (SITL).

Each case plans a flight with ``mavsysid plan --vehicle quad_x`` (fixed sample budget and
seed: the same plan on any machine), starts ``../shared/sitl/arducopter`` (X frame, stock
parameters, loopback TCP only) and flies the plan with ``mavsysid stream``, then prints the
tracking RMS / max (the streamer's own: position against setpoint over the trajectory,
``meta.json`` ``tracking``) and the achieved setpoint rate and p99 period deviation
(``meta.json`` ``setpoints``):

- ``set-limits``: planned with ``--autopilot-limits tests/data/sitl_quad_calibration.parm``
  (raised limits) and flown on stock ArduCopter with ``--set-limits``;
- ``stock-plan``: planned with ``--autopilot-limits`` of the stock values the first flight
  read from SITL (``meta.json`` ``autopilot_limits.read``), flown without ``--set-limits``.

    python bench/sitl_tracking.py [--budget 15] [--samples 400] [--seed 4] [--speedup 1]

``--speedup K`` runs SITL and the streamer's clock K× faster than real time; on a loaded
machine SITL may fall behind its nominal speed-up while the streamer keeps the wall clock ×
K, so the figures are measured at 1.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.support.sitl import running_sitl  # noqa: E402
from tests.support.stream_flights import flight_dir, run_stream  # noqa: E402

DATA = REPO / "tests" / "data"
STOCK_PARMS = DATA / "sitl_quad_x_stock.parm"
RAISED_PARMS = DATA / "sitl_quad_calibration.parm"


def _plan(work: Path, limits: Path, args: argparse.Namespace) -> Path:
    out = work / f"plan_{limits.stem}.json"
    done = subprocess.run([sys.executable, "-m", "mavsysid", "-q", "plan", "--vehicle", "quad_x",
                           "--budget", f"{args.budget:g}", "--samples", str(args.samples),
                           "--time", "0", "--refine-steps", "300", "--seed", str(args.seed),
                           "--autopilot-limits", str(limits), "-o", str(out)],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"plan failed: {done.stderr.strip()}")
    return out


def _fly(work: Path, name: str, plan: Path, extra: tuple[str, ...],
         speedup: float) -> dict[str, Any]:
    """One SITL flight of ``plan``; its meta.json (or the refusal)."""
    logs = work / f"logs_{name}"
    with running_sitl(work / f"sitl_{name}", defaults=[STOCK_PARMS], model="x",
                      speedup=speedup) as sitl:
        done = run_stream(plan, "--connect", sitl.connect, "--vehicle", "quad_x",
                          "--speedup", f"{speedup:g}", "--log-dir", str(logs), *extra,
                          cwd=work, timeout=600.0, lockstep=False)
    if done.returncode != 0:
        return {"failed": done.stderr.strip().splitlines()[-1:]}
    return json.loads((flight_dir(logs) / "meta.json").read_text())


def _report(name: str, meta: dict[str, Any]) -> None:
    if "failed" in meta:
        print(f"{name:11s} not flown: {meta['failed']}")
        return
    t, s = meta.get("tracking", {}), meta.get("setpoints", {})
    peaks = meta.get("autopilot_limits", {}).get("plan_peaks_si", {})
    print(f"{name:11s} tracking RMS {t.get('rms_m', float('nan')):.3f} m, max "
          f"{t.get('max_m', float('nan')):.3f} m over {t.get('rows', 0)} rows; setpoints "
          f"{s.get('rate_hz', float('nan')):.2f} Hz (nominal {s.get('nominal_rate_hz', 0):g}), "
          f"p99 period deviation {1e3 * s.get('period_deviation_p99_s', float('nan')):.2f} ms,"
          f" {s.get('sent', 0)} sent; plan peaks accel_xy {peaks.get('accel_xy', 0):.2f} m/s²,"
          f" jerk_xy {peaks.get('jerk_xy', 0):.1f} m/s³, yaw rate "
          f"{57.29578 * peaks.get('yaw_rate', 0):.0f}°/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=15.0)
    parser.add_argument("--samples", type=int, default=400)
    parser.add_argument("--seed", type=int, default=4)
    parser.add_argument("--speedup", type=float, default=1.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="sitl_tracking_") as tmp:
        work = Path(tmp)
        raised = _fly(work, "set-limits", _plan(work, RAISED_PARMS, args), ("--set-limits",),
                      args.speedup)
        _report("set-limits", raised)
        read = raised.get("autopilot_limits", {}).get("read")
        if not read:
            print("stock-plan  skipped: the first flight recorded no autopilot limits")
            return
        stock = work / "stock_read.parm"
        stock.write_text("".join(f"{k} {v:g}\n" for k, v in read.items()))
        _report("stock-plan", _fly(work, "stock-plan", _plan(work, stock, args), (),
                                   args.speedup))


if __name__ == "__main__":
    main()
