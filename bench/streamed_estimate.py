"""θ from a streamed flight of our simulated autopilot, against its truth.

`mavsysid sim --lockstep --truth-log DIR` (the Firefly, its sensor noise on, seeded) flies
the built-in excitation figure streamed by `mavsysid stream --lockstep` over UDP on
127.0.0.1, both sped up; then `mavsysid estimate FLIGHT/pose.csv --truth DIR` reads what a
ground station recorded (the autopilot's pose telemetry and ESC rpm at the rate asked for)
and prints each parameter's error and z = error / σ. The path every real-autopilot flight
takes, with a known truth.

    nice python bench/streamed_estimate.py [--seed 1] [--duration 30] [--work DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.flight.loopback_ports import free_udp_port

from tests.support.stream_flights import SimProcess, export_excitation, flight_dir, run_stream


def fly_and_estimate(work: Path, seed: int, duration: float) -> str:
    """Fly, estimate; ``estimate``'s output (its truth table included)."""
    trajectory = export_excitation(work / "figure.json", duration)
    port = free_udp_port()
    with SimProcess(work / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup", "4",
                    "--seed", str(seed), "--truth-log", str(work / "truth")) as sim:
        flown = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup", "4",
                           "--log-dir", str(work / "logs"), cwd=work, timeout=900)
        if flown.returncode != 0:
            raise SystemExit(f"stream exit {flown.returncode}: {flown.stderr}{sim.output()}")
    flight = flight_dir(work / "logs")
    done = subprocess.run([sys.executable, "-m", "mavsysid", "estimate", str(flight / "pose.csv"),
                           "--vehicle", "firefly", "--truth", str(work / "truth"), "-o",
                           str(flight / "estimate.json")],
                          capture_output=True, text=True, check=False)
    return f"{flight}\nestimate exit {done.returncode}\n{done.stdout}{done.stderr}"


def main() -> None:
    """Run the bench."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--work", type=Path, help="keep the flight here (default: a temporary "
                        "folder)")
    args = parser.parse_args()
    if args.work is not None:
        args.work.mkdir(parents=True, exist_ok=True)
        print(fly_and_estimate(args.work, args.seed, args.duration))
        return
    with tempfile.TemporaryDirectory() as tmp:
        print(fly_and_estimate(Path(tmp), args.seed, args.duration))


if __name__ == "__main__":
    main()
