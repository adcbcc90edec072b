"""``mavsysid experiment`` on ArduCopter SITL, per seed, against SITL's reference θ.

Per seed: starts ``../shared/sitl/arducopter --model x`` (loopback TCP only) with
``copter.parm`` and ``vehicle/configs/sitl_quad.parm``, runs ``mavsysid experiment
--connect tcp:127.0.0.1:PORT --vehicle sitl_quad --budget B --samples N --refine-steps R
--seed S --prearm-timeout 300`` (the limits read from SITL, its stock ones; a loaded
machine slows SITL's EKF start; the experiment starts as soon as SITL listens, and the
streamer waits for its pre-arm checks), stops SITL by its PID, and prints the command's
exit code and last line (its whole output in ``DIR/seedS/experiment.out``). Then what it
wrote: the flight's share of the budget, the tracking error, and ``estimate.json`` per
parameter (value, σ, status, source, error against the reference, whether the reference
lies in value ± 1.96 σ). Then, on the flight's own ``flight.tlog``, per
parameter against `vehicle/configs/sitl_quad.toml`'s reference (docs/vehicles/sitl_quad.md):
what ``estimate`` computes before its checks (the EKF and batch refinement, the final
estimate) and the force and torque balance
(`mavsysid.estimation.balance.fit.fit_wrench_balance`, with its determination status).

    python bench/sitl_experiment.py [--seeds 1 2 3] [--budget 20] [--samples 200]
        [--refine-steps 300] [--keep DIR]
    python bench/sitl_experiment.py --report DIR [--seeds ...]   # flights kept in DIR
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.support.sitl import running_sitl  # noqa: E402

SITL_PARMS = REPO / "vehicle" / "configs" / "sitl_quad.parm"
def per_parameter(log: Path) -> None:
    """The final estimate and the balance on ``log``, each parameter against the reference."""
    from mavsysid.estimation.balance.fit import fit_wrench_balance
    from mavsysid.estimation.filter.estimator import estimate_parameters
    from mavsysid.estimation.readers import load_flight
    from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

    config = load_vehicle("sitl_quad")
    reference = config.theta
    flight = load_flight(log, config)
    final = estimate_parameters(flight, config, None).final
    balance = fit_wrench_balance(flight, config)
    print(f"  {'':4s} {'reference':>10s} | {'estimate (EKF + refinement)':>34s} | "
          "force and torque balance")
    for i, name in enumerate(PARAMETER_NAMES):
        rows = []
        for value, sigma in ((final.value[i], final.sigma[i]),
                             (balance.estimate.value[i], balance.estimate.sigma[i])):
            error = 100 * (value / reference[i] - 1)
            rows.append(f"{value:10.4g} ± {sigma:8.2g} ({error:+6.1f} %, "
                        f"{(value - reference[i]) / sigma:+5.1f} σ)")
        print(f"  {name:4s} {reference[i]:10.4g} | {rows[0]} | {rows[1]} {balance.status[i]}")


def answered(flight: Path, budget: float) -> None:
    """What ``experiment`` wrote: budget use, tracking, and ``estimate.json`` per parameter
    (value, σ, status, source, error against the reference, reference in value ± 1.96 σ)."""
    from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

    reference = load_vehicle("sitl_quad").theta
    duration = json.loads((flight / "trajectory.json").read_text())["duration"]
    tracking = json.loads((flight / "meta.json").read_text()).get("tracking", {})
    print(f"  flight {duration:.2f} s of {budget:g} s ({100 * duration / budget:.0f} %), "
          f"tracking RMS {100 * tracking.get('rms_m', float('nan')):.1f} cm, "
          f"max {100 * tracking.get('max_m', float('nan')):.1f} cm")
    path = flight / "estimate.json"
    if not path.is_file():
        print("  no estimate.json")
        return
    answer = json.loads(path.read_text())
    print(f"  estimate.json: mismatch {answer.get('mismatch')}, "
          f"filter refusal {answer.get('filter_refusal')}")
    for i, name in enumerate(PARAMETER_NAMES):
        entry = answer["parameters"][name]
        value, sigma = entry["value"], entry["sigma"]
        inside = abs(value - reference[i]) <= 1.96 * sigma
        error = 100 * (value / reference[i] - 1)
        print(f"  {name:4s} {value:10.4g} ± {sigma:8.2g}  {error:+6.1f} %"
              f"  {(value - reference[i]) / sigma:+5.1f} σ  ref {'inside' if inside else 'OUTSIDE'}"
              f" 95 %  {entry.get('status')} ({entry.get('source')})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--budget", type=float, default=20.0)
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--refine-steps", type=int, default=300)
    parser.add_argument("--keep", type=Path, help="keep the flights here")
    parser.add_argument("--report", type=Path,
                        help="only report on the flights a --keep run left in this folder")
    args = parser.parse_args()
    if args.report:
        for seed in args.seeds:
            logs = args.report / f"seed{seed}" / "logs"
            for flight in sorted(p for p in logs.iterdir() if p.is_dir()):
                print(f"seed {seed}: {flight}")
                answered(flight, args.budget)
                per_parameter(flight / "flight.tlog")
        return
    work = args.keep or Path(tempfile.mkdtemp(prefix="sitl-experiment-"))
    for seed in args.seeds:
        logs = work / f"seed{seed}" / "logs"
        with running_sitl(work / f"seed{seed}" / "sitl", defaults=[SITL_PARMS],
                          model="x") as sitl:
            done = subprocess.run(
                [sys.executable, "-m", "mavsysid", "experiment", "--connect", sitl.connect,
                 "--vehicle", "sitl_quad", "--budget", f"{args.budget:g}", "--samples",
                 str(args.samples), "--refine-steps", str(args.refine_steps), "--seed",
                 str(seed), "--prearm-timeout", "300", "--log-dir", str(logs)],
                capture_output=True, text=True, check=False)
        (work / f"seed{seed}" / "experiment.out").write_text(done.stdout + done.stderr)
        last = (done.stderr.strip().splitlines() or [""])[-1]
        print(f"seed {seed}: exit {done.returncode}" + ("" if done.returncode == 0
                                                        else f": {last}"), flush=True)
        flights = [p for p in logs.iterdir() if p.is_dir()] if logs.is_dir() else []
        flown = flights and json.loads((flights[0] / "meta.json").read_text()).get(
            "status") == "complete"
        if flown:
            answered(flights[0], args.budget)
            per_parameter(flights[0] / "flight.tlog")
        sys.stdout.flush()
    print(f"flights in {work}")


if __name__ == "__main__":
    main()
