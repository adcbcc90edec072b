"""Why planned flights saturate on their own vehicle: rotor headroom, motor lag, rotor drag.

Plans with the true θ as the planner's model (so the prior is not the cause), for each
rotor headroom, and flies each plan in the offline simulator four ways: with and without
the truth's motor lag, with and without rotor drag (c_D → 0 in truth and plan). Prints
the share of control ticks on which a rotor command was clipped (yaw given up counts)
and the tracking RMS.

    nice python bench/headroom_saturation.py [--vehicle firefly] [--seeds 3]
        [--headroom 0 0.05 0.1] [--samples 600] [--refine-steps 3000]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicle", default="firefly")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--headroom", type=float, nargs="+", default=[0.0, 0.05, 0.1])
    parser.add_argument("--samples", type=int, default=600)
    parser.add_argument("--refine-steps", type=int, default=3000)
    args = parser.parse_args()
    truth = load_vehicle(args.vehicle)
    no_drag = truth.with_parameters(truth.theta * np.array([1.0, 1e-9, 1.0, 1.0, 1.0, 1.0]))
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        for seed in range(args.seeds):
            for headroom in args.headroom:
                result = plan(truth, PlannerSettings(
                    budget=30.0, planning_time=np.inf, max_samples=args.samples,
                    refine_steps=args.refine_steps, seed=seed, rotor_headroom=headroom))
                cells = []
                for lag in (True, False):
                    for vehicle, drag in ((truth, True), (no_drag, False)):
                        flown = SimulationSettings(seed=seed, motor_lag=lag)
                        sim = Simulator(vehicle, true_theta=vehicle.theta, settings=flown).run(
                            result.trajectory, tmp / f"{seed}-{headroom}-{lag}-{drag}")
                        cells.append(f"lag {lag:d} drag {drag:d}: {sim.saturated_fraction:5.1%}"
                                     f" {100 * sim.position_rms:.1f} cm")
                print(f"seed {seed} headroom {headroom:g} ({result.trajectory.duration:.0f} s, "
                      f"D-opt {result.predicted_dopt:.3g}): " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
