"""Lock-step under load: the same streamed flight on an idle and on an overloaded machine.

Flies the built-in excitation figure with ``mavsysid stream`` against ``mavsysid sim``
(ArduPilot personality, UDP loopback, both as their own processes), once per mode and
load: lock-step (``--lockstep`` on both sides) and the wall clock, each idle and with
``--load N`` busy processes (``while :; do :; done``) competing for the cores. Prints per
run: exit code, pose-log samples, tracking RMS and max (the streamer's meta.json), the
setpoints sent, and the wall time of the stream command.

    python bench/lockstep_load.py [--duration 10] [--speedup 4] [--load 4]
        [--modes lockstep,wall] [--no-noise]

Lock-step should give the same sample count and tracking idle and loaded (it only runs
slower); the wall clock loses samples and tracking under load.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mavsysid.flight.loopback_ports import free_udp_port  # noqa: E402

from tests.support.stream_flights import (  # noqa: E402
    SimProcess,
    export_excitation,
    flight_dir,
    run_stream,
)

__all__ = ["fly_once", "main"]


def fly_once(trajectory: Path, work: Path, speedup: float, lockstep: bool,
             sim_args: tuple[str, ...] = ()) -> dict:
    """One flight; its figures."""
    port = free_udp_port()
    logs = work / "logs"
    start = time.monotonic()
    with SimProcess(work / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    f"{speedup:g}", *sim_args, lockstep=lockstep) as sim:
        result = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup",
                            f"{speedup:g}", "--log-dir", str(logs), cwd=work, timeout=900,
                            lockstep=lockstep)
        sim_line = sim.stop().strip().splitlines()[-1]
    wall = time.monotonic() - start
    out = {"code": result.returncode, "wall_s": wall, "sim": sim_line}
    if result.returncode != 0:
        out["error"] = result.stderr.strip().splitlines()[-1:]
        return out
    meta = json.loads((flight_dir(logs) / "meta.json").read_text())
    out.update(samples=meta["samples"], rms_cm=100 * meta["tracking"]["rms_m"],
               max_cm=100 * meta["tracking"]["max_m"], setpoints=meta["setpoints"]["sent"])
    return out


def _busy(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen(["sh", "-c", "while :; do :; done"]) for _ in range(n)]


def main() -> None:
    """Run the bench and print one line per flight."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--speedup", type=float, default=4.0)
    p.add_argument("--load", type=int, default=4)
    p.add_argument("--modes", default="lockstep,wall")
    p.add_argument("--no-noise", action="store_true", help="the sim publishes the truth")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        trajectory = export_excitation(Path(tmp) / "figure.json", args.duration)
        for mode in args.modes.split(","):
            for load in (0, args.load):
                work = Path(tmp) / f"{mode}_{load}"
                work.mkdir()
                hogs = _busy(load)
                try:
                    r = fly_once(trajectory, work, args.speedup, mode == "lockstep",
                                 ("--no-noise",) if args.no_noise else ())
                finally:
                    for h in hogs:
                        h.kill()
                        h.wait()
                figures = (f"samples {r['samples']}, tracking RMS {r['rms_cm']:.2f} cm, max "
                           f"{r['max_cm']:.2f} cm, setpoints {r['setpoints']}"
                           if r["code"] == 0 else f"failed: {r.get('error')}")
                print(f"{mode:8s} load {load}: exit {r['code']}, {figures}, "
                      f"{r['wall_s']:.1f} s wall", flush=True)
                print(f"    {r['sim']}", flush=True)


if __name__ == "__main__":
    main()
