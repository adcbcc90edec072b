"""What the plan predicts against what ``estimate`` then reports, per parameter.

For each flown flight (a flight directory holding ``trajectory.json``, the streamed plan,
and ``estimate.json``, what ``mavsysid estimate`` answered), θ's σ is predicted by the
planner's own recursion (`mavsysid.experiments.data_efficiency.belief_history`) along the
flight the autopilot's loop is predicted to fly (``--loop FILE``, its parameters as
``plan --autopilot-model`` reads them; without it the setpoints are flown exactly), at
the vehicle file's θ and prior σ, for three noise models:

* ``file``: the vehicle file's ``[noise]`` and a 100 Hz pose (what ``plan`` assumes by
  default);
* ``others``: the noise the estimator met on the *other* flights given (the median of each
  quantity, `NoiseMet.median`): what ``plan --noise-from`` on earlier flights of the
  vehicle gives;
* ``own``: the noise met on this flight itself (in-sample: the best the noise model can do).

Reported per flight and model: reached σ / predicted σ per parameter, where the reached σ is
the answer's (the prior's, 50 %, for a parameter not determined), and the plan's
expectation (determined when predicted σ ≤ 12.5 % of θ and, for *others*, not set aside on
at least half of the other flights, as ``plan --noise-from`` prints it) against
``estimate``'s status, counted over the flights.

    python bench/predicted_vs_reached.py FLIGHT_DIR... --vehicle sitl_quad \\
        [--loop bench/sitl_loop.parm] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

MODELS = ("file", "others", "own")


def predicted(config, trajectory, loop, met) -> np.ndarray:
    """θ's predicted final σ (SI, shape (6,)) of ``trajectory`` flown by ``loop``."""
    from mavsysid.experiments.data_efficiency import belief_history
    from mavsysid.pipeline.plan import for_noise_met
    from mavsysid.planner.settings import PlannerSettings

    model, settings = for_noise_met(config, PlannerSettings(autopilot=loop), met)
    return belief_history(model, trajectory, settings).sigma[-1]


def reached(flight: Path) -> tuple[np.ndarray, list[str], list[str]]:
    """The answer's σ (SI), status and source per parameter of θ."""
    from mavsysid.vehicle.config import PARAMETER_NAMES

    answer = json.loads((flight / "estimate.json").read_text())["parameters"]
    return (np.array([answer[n]["sigma"] for n in PARAMETER_NAMES]),
            [answer[n]["status"] for n in PARAMETER_NAMES],
            [answer[n]["source"] for n in PARAMETER_NAMES])


def noise_of(flight: Path):
    """The noise the filter met on ``flight``, or None where its filter was refused."""
    from mavsysid.estimation import read_noise_met

    from mavsysid.errors import InputError

    try:
        return read_noise_met(flight)
    except InputError:
        return None


def run(flights: list[Path], vehicle: str, loop_file: Path | None) -> list[dict]:
    """One row per flight: reached/predicted per model, expectations and statuses."""
    from mavsysid.estimation import noise_from_flights
    from mavsysid.formats.parameter_file import read_parameter_file
    from mavsysid.formats.trajectory_file import read_trajectory
    from mavsysid.vehicle.autopilot_loop import AutopilotLoop
    from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle
    from mavsysid.vehicle.parameters import MAX_RELATIVE_SIGMA

    config = load_vehicle(vehicle)
    loop = (None if loop_file is None else
            AutopilotLoop.from_parameters("ardupilot", read_parameter_file(loop_file)))
    mets = [noise_of(f) for f in flights]
    rows = []
    for i, flight in enumerate(flights):
        trajectory = read_trajectory(flight / "trajectory.json").trajectory
        sigma, status, source = reached(flight)
        row = {"flight": str(flight), "status": status, "source": source,
               "reached_rel": (sigma / config.theta).tolist()}
        # What `plan --noise-from` on the other flights (those whose filter ran) gives.
        known = [f for j, f in enumerate(flights) if j != i and mets[j] is not None]
        others, set_aside = noise_from_flights(known) if known else (None, ())
        for model, met in zip(MODELS, (None, others, mets[i]), strict=True):
            if model != "file" and met is None:
                row[model] = None  # no filter ran on the flight(s): no noise met
                continue
            pred = predicted(config, trajectory, loop, met)
            aside = set_aside if model == "others" else ()
            row[model] = {"ratio": (sigma / pred).tolist(),
                          "predicted_rel": (pred / config.theta).tolist(),
                          "expected": [bool(p <= MAX_RELATIVE_SIGMA * t) and n not in aside
                                       for n, p, t in zip(PARAMETER_NAMES, pred, config.theta,
                                                          strict=True)]}
        rows.append(row)
        print_row(row)
    return rows


def print_row(row: dict) -> None:
    """The flight's reached σ, and per model reached/predicted per parameter."""
    from mavsysid.vehicle.config import PARAMETER_NAMES

    print(Path(row["flight"]).name)
    print("  reached σ/θ %  " + "  ".join(
        f"{n} {100 * r:6.2f}{'' if s == 'determined' else '*'}"
        for n, r, s in zip(PARAMETER_NAMES, row["reached_rel"], row["status"], strict=True)))
    for model in MODELS:
        if row[model] is None:
            print(f"  {model:6s} no noise met (the filter was refused)")
            continue
        cells = "  ".join(f"{n} {r:6.2f}{'' if e else '~'}" for n, r, e in zip(
            PARAMETER_NAMES, row[model]["ratio"], row[model]["expected"], strict=True))
        print(f"  {model:6s} reached/pred  {cells}")
    print("  (* not determined: the prior's σ; ~ the plan expected it not determined)",
          flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("flights", type=Path, nargs="+")
    parser.add_argument("--vehicle", default="sitl_quad")
    parser.add_argument("--loop", type=Path, help="the autopilot's parameters (.parm)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    rows = run(args.flights, args.vehicle, args.loop)
    for model in MODELS:
        pairs = [(e, s == "determined") for r in rows if r[model] is not None
                 for e, s in zip(r[model]["expected"], r["status"], strict=True)]
        agree = sum(e == s for e, s in pairs)
        print(f"{model:6s} expected status = estimate's on {agree} of {len(pairs)} "
              "parameter-flights")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
