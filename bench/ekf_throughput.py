"""EKF throughput on a 60 s, 200 Hz pose log, as a multiple of real time (floor 50×, target 200×).

Simulates the reference vehicle flying a 60 s excitation logged at 200 Hz, then times
the compiled filter over it (after a warm-up run), and the whole pipeline (filter, noise
fit, batch refinement) for comparison.

    python bench/ekf_throughput.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.filter.estimator import (
    EstimatorSettings,
    estimate_parameters,
    flight_initial_state_sigma,
)
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import prior_from_config
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import load_vehicle


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cfg = load_vehicle("firefly")
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp) / "f"
        settings = SimulationSettings(control_rate=1000.0, log_rate=200.0, seed=1)
        Simulator(cfg, settings=settings).run(
            excitation_trajectory(ExcitationSpec(duration=60.0)), directory)
        flight = load_flight(directory / "pose.csv", cfg)
    prior = prior_from_config(cfg, EstimatorSettings())
    sigma = (cfg.noise.position_sigma, cfg.noise.attitude_sigma)
    state_sigma = flight_initial_state_sigma(flight, sigma)
    ParameterEKF(cfg, prior, sigma).run(flight, state_sigma)  # warm-up (numba cache load)
    walls = []
    for _ in range(args.repeats):
        ekf = ParameterEKF(cfg, prior, sigma)
        start = time.perf_counter()
        ekf.run(flight, state_sigma)
        walls.append(time.perf_counter() - start)
    wall = statistics.median(walls)
    start = time.perf_counter()
    estimate_parameters(flight, cfg)
    pipeline = time.perf_counter() - start
    print(f"log: {flight.duration:.0f} s at 200 Hz ({len(flight)} samples)")
    print(f"EKF: {wall * 1000:.0f} ms = {flight.duration / wall:.0f}x real time "
          f"({wall / len(flight) * 1e6:.1f} µs per sample; median of {args.repeats})")
    print(f"filter + noise fit + batch refinement: {pipeline:.1f} s = "
          f"{flight.duration / pipeline:.1f}x real time")


if __name__ == "__main__":
    main()
