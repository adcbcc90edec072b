"""What the IMU adds to `estimate`: simulated quad_x flights with and without their IMU.

Each seed flies the built-in excitation (30 s, logged at 250 Hz with the IMU on the pose
rows: noise and constant biases of the vehicle's ``[noise]``) and runs `estimate` three
times from a prior 30 % off (c_T, c_M × 1.3; c_D, J × 0.7): with the IMU removed
("pose only"), with it as `estimate` reads it by default (the force and torque balance
reads it, the filter the pose: "IMU"), and with the filter reading it too
(``--filter-imu``: "IMU, filter too"). Printed per flight and parameter: the
answer's σ and error (%), its error in σ, and the time of the whole `estimate`
(in-process, compiled kernels cached).

    nice python bench/imu_filter.py [--seeds 1 2 3] [--duration 30]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from mavsysid.estimation import EstimatorSettings, estimate
from mavsysid.estimation.readers import load_flight
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

PRIOR_FACTORS = np.array([1.3, 0.7, 1.3, 0.7, 0.7, 0.7])


def _truth(directory: Path, theta: np.ndarray) -> dict[str, float]:
    imu = json.loads((directory / "meta.json").read_text())["truth"]["imu"]
    out = dict(zip(PARAMETER_NAMES, theta, strict=True))
    for i, a in enumerate("xyz"):
        out[f"gyro_bias_{a}"] = imu["gyro_bias_rad_s"][i]
        out[f"accel_bias_{a}"] = imu["accel_bias_m_s2"][i]
        out[f"imu_{a}"] = imu["position_m"][i]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--duration", type=float, default=30.0)
    args = parser.parse_args()
    cfg = load_vehicle("quad_x")
    prior = cfg.with_parameters(cfg.theta * PRIOR_FACTORS)
    with tempfile.TemporaryDirectory(prefix="imu-filter-") as tmp:
        for seed in args.seeds:
            directory = Path(tmp) / f"seed{seed}"
            Simulator(cfg, settings=SimulationSettings(seed=seed, log_rate=250.0)).run(
                excitation_trajectory(ExcitationSpec(duration=args.duration)), directory)
            flight = load_flight(directory / "pose.csv", cfg)
            truth = _truth(directory, cfg.theta)
            runs = (("pose only", replace(flight, imu=None), EstimatorSettings()),
                    ("IMU", flight, EstimatorSettings()),
                    ("IMU, filter too", flight, EstimatorSettings(filter_imu=True)))
            for label, data, settings in runs:
                t0 = time.perf_counter()
                result = estimate(data, prior, settings)
                seconds = time.perf_counter() - t0
                final = result.final
                print(f"seed {seed}, {label}: estimate {seconds:.1f} s")
                for i, name in enumerate(final.names):
                    value, sigma, true = final.value[i], final.sigma[i], truth[name]
                    relative = (f"σ {100 * sigma / abs(true):.2g} %, error "
                                f"{100 * (value / true - 1):+.2g} %, " if true else "")
                    print(f"  {name:13s} {value: .6g} ± {sigma:.3g}  {relative}"
                          f"{(value - true) / sigma:+.2f} σ")


if __name__ == "__main__":
    main()
