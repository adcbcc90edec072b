"""Offline simulation speed as a multiple of real time (target: ≥ 20× at 1 kHz physics).

Flies the reference vehicle along the built-in 30 s excitation trajectory with 1 kHz
RK4 physics, motor lag and the geometric controller, with and without writing the
flight logs, and prints the median real-time factor over several runs (after one
warm-up run that loads numba's compiled kernels).

    python bench/sim_speed.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from mavsysid.flight.offline.excitation import excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import load_vehicle


def measure(vehicle: str, control_rate: float, log: bool, repeats: int) -> tuple[float, float]:
    """(median real-time factor, median position RMS in m) over ``repeats`` runs."""
    cfg = load_vehicle(vehicle)
    trajectory = excitation_trajectory()
    settings = SimulationSettings(physics_rate=1000.0, control_rate=control_rate)
    sim = Simulator(cfg, settings=settings)
    sim.run(trajectory)  # warm-up: numba loads or compiles its kernels
    factors, rms = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            start = time.perf_counter()
            result = sim.run(trajectory, Path(tmp) / f"f{i}" if log else None)
            wall = time.perf_counter() - start
            factors.append(trajectory.duration / wall)
            rms.append(result.position_rms)
    return statistics.median(factors), statistics.median(rms)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print("vehicle     physics  control  logs   real-time factor  position RMS")
    for vehicle in ("firefly", "quad_x", "micro_quad"):
        for control, log in ((500.0, True), (500.0, False), (1000.0, True)):
            factor, rms = measure(vehicle, control, log, args.repeats)
            print(f"{vehicle:<11} 1000 Hz  {control:>4.0f} Hz  {'yes' if log else 'no ':<5}"
                  f"  {factor:>8.0f}x          {1000 * rms:.1f} mm")


if __name__ == "__main__":
    main()
