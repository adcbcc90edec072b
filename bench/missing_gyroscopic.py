"""The planned flight against the practitioner's where the truth lacks ω × Jω, as ArduCopter
SITL's physics do (docs/vehicles/sitl_quad.md): is that what costs the plan on SITL?

Per seed, in the offline simulator with `sitl_quad` as the truth (SITL's limits and
geometry, `bench/sitl_loop.parm`'s envelope), the plan (`mavsysid.planner.rrbt.plan`, 20 s)
and the practitioner's Lissajous with yaw at the same limits
(`mavsysid.experiments.baselines.practitioner_excitation`) are each flown in two worlds:
*full* (the paper's rigid body) and *no-gyro* (a hidden torque +ω × Jω cancels the
gyroscopic term, as SITL integrates ω̇ = τ / J per axis), and estimated as ``mavsysid
estimate`` does (`mavsysid.pipeline.estimate.run_estimate` on the flight's ``pose.csv``).
Reported: D-opt det(Σθ)^(1/6) of the answer (a parameter not determined at its prior σ)
and of the filter's run at the configured noise (what the plan predicts), the process-noise
level the estimate fitted to the flight (× the configured densities), the RMS rate of
change of the rotor speeds each flight asks for,
and per parameter the error, "!" where the truth lies outside value ± 1.96 σ, and "—"
where it is not determined.

    nice python bench/missing_gyroscopic.py [--seeds 1 2 3] [--samples 200] [--time T]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from mavsysid.flight.offline.effects import TruthEffect  # noqa: E402


class WithoutGyroscopic(TruthEffect):
    """A hidden body torque +ω × Jω: the truth's ω̇ = τ / J per axis, as SITL's."""

    name = "no_gyroscopic"

    def bind(self, true_theta, rotor_positions, rotor_directions=None) -> None:
        self.inertia = np.asarray(true_theta[3:6], dtype=float)

    def wrench(self, t, x, n):
        w = np.asarray(x[10:13], dtype=float)
        return np.zeros(3), np.cross(w, self.inertia * w)


def rotor_rate_rms(trajectory, config) -> float:
    """RMS rate of change of the rotor speeds the trajectory asks for (flatness), rad/s²."""
    from mavsysid.vehicle.flatness import flat_to_state

    t = np.arange(0.0, trajectory.duration, 0.002)
    n = np.sqrt(np.clip(flat_to_state(trajectory.flat_outputs(t), config)
                        .rotor_speeds_squared, 0.0, None))
    return float(np.sqrt(np.mean(np.gradient(n, t, axis=0) ** 2)))


def fly_and_estimate(trajectory, config, world: str, seed: int, directory: Path) -> dict:
    """The answer's D-opt, errors (%) and statuses of ``trajectory`` flown in ``world``."""
    from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
    from mavsysid.pipeline.estimate import run_estimate
    from mavsysid.vehicle.config import PARAMETER_NAMES

    effects = [WithoutGyroscopic()] if world == "no-gyro" else []
    Simulator(config, settings=SimulationSettings(seed=seed), effects=effects).run(
        trajectory, directory)
    result = run_estimate(directory / "pose.csv", config.name).result
    six = len(PARAMETER_NAMES)
    final = result.final
    error = 100 * (final.value[:six] / config.theta - 1)
    covered = np.abs(final.value[:six] - config.theta) <= 1.96 * final.sigma[:six]
    met = result.noise_met
    with np.errstate(invalid="ignore", divide="ignore"):
        dopt, filter_dopt = final.d_optimality, result.filtered.d_optimality
    return {"dopt": dopt if np.isfinite(dopt) else float("nan"), "filter_dopt": filter_dopt,
            "noise_scale": (float("nan") if met is None
                            else met.force_density / config.noise.force_density),
            "error": error.tolist(), "status": list(result.status[:six]),
            "covered": covered.tolist()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--budget", type=float, default=20.0)
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--time", type=float, help="plan for this wall time instead")
    args = parser.parse_args()
    from mavsysid.experiments.baselines import practitioner_excitation
    from mavsysid.planner.rrbt import plan
    from mavsysid.planner.settings import PlannerSettings
    from mavsysid.vehicle.config import PARAMETER_NAMES

    from bench.autopilot_information import sitl_setup

    config, limits, _ = sitl_setup()
    for seed in args.seeds:
        settings = PlannerSettings(budget=args.budget, seed=seed, autopilot_limits=limits,
                                   planning_time=args.time or np.inf,
                                   max_samples=None if args.time else args.samples,
                                   refine_steps=100_000 if args.time else 300)
        flights = {"planned": plan(config, settings).trajectory,
                   "practitioner": practitioner_excitation(config, settings).trajectory}
        for kind, trajectory in flights.items():
            rate = rotor_rate_rms(trajectory, config)
            print(f"seed {seed} {kind:12s} rotor-speed rate {rate:.1f} rad/s² RMS", flush=True)
        for world in ("full", "no-gyro"):
            for kind, trajectory in flights.items():
                with tempfile.TemporaryDirectory() as tmp:
                    row = fly_and_estimate(trajectory, config, world, seed, Path(tmp))
                cells = "  ".join(
                    f"{n} {e:+6.1f}{'' if c else '!'}{'' if s == 'determined' else ' —'}"
                    for n, e, s, c in zip(PARAMETER_NAMES, row["error"], row["status"],
                                          row["covered"], strict=True))
                print(f"seed {seed} {world:8s} {kind:12s} D-opt {row['dopt']:9.3g} (filter at "
                      f"the configured noise {row['filter_dopt']:.3g}; noise fitted "
                      f"{row['noise_scale']:.3g} ×)  {cells}", flush=True)


if __name__ == "__main__":
    main()
