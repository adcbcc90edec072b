"""One flight, two logs: do the estimates from its tlog and its autopilot log agree?

Each pair is two ``estimate.json`` files of the same flight (``mavsysid estimate
flight.tlog -o A``, ``mavsysid estimate autopilot.bin -o B``). Per parameter both
determine, the difference in σ of the difference, √(σ_A² + σ_B²) (two estimates of one
flight are not independent, so this is the lenient denominator; the acceptance asks for
2 σ), and each one's error to the vehicle file's θ where that is a reference (SITL's
`sitl_quad`).

    python bench/log_agreement.py A.json B.json [A.json B.json ...] --vehicle sitl_quad
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.parameters import PARAMETER_NAMES

#: Two estimates of one flight agree when they differ by at most this many σ.
AGREEMENT_SIGMAS = 2.0


def _determined(path: Path) -> dict[str, dict]:
    parameters = json.loads(path.read_text())["parameters"]
    return {name: p for name, p in parameters.items()
            if name in PARAMETER_NAMES and p.get("status") == "determined"}


def compare(first: Path, second: Path, reference: dict[str, float]) -> list[str]:
    """One line per parameter either file determines: both values and their difference."""
    a, b = _determined(first), _determined(second)
    lines = []
    def cell(p: dict, ref: float) -> str:
        return (f"{100 * (p['value'] / ref - 1):+.1f} ± {100 * p['sigma'] / ref:.1f} % "
                f"({p['source']})")

    for name in PARAMETER_NAMES:
        if name not in a and name not in b:
            continue
        ref = reference[name]
        if name in a and name in b:
            z = (a[name]["value"] - b[name]["value"]) / math.hypot(a[name]["sigma"],
                                                                   b[name]["sigma"])
            flag = "" if abs(z) <= AGREEMENT_SIGMAS else "  DISAGREE"
            lines.append(f"  {name:4s} {cell(a[name], ref):28s} | {cell(b[name], ref):28s} | "
                         f"{z:+.1f} σ{flag}")
        else:
            which, p = (first.name, a[name]) if name in a else (second.name, b[name])
            lines.append(f"  {name:4s} only {which}: {cell(p, ref)}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("estimates", nargs="+", type=Path, help="pairs of estimate.json")
    parser.add_argument("--vehicle", required=True, help="the reference θ")
    args = parser.parse_args()
    if len(args.estimates) % 2:
        parser.error("give the estimates in pairs (the tlog's, then the autopilot log's)")
    reference = dict(zip(PARAMETER_NAMES, load_vehicle(args.vehicle).theta, strict=True))
    for first, second in zip(args.estimates[::2], args.estimates[1::2], strict=True):
        print(f"{first} | {second}")
        print("\n".join(compare(first, second, reference)))


if __name__ == "__main__":
    main()
