"""``mavsysid experiment`` on real ArduCopter (SITL, ``../shared/sitl``, loopback TCP only):
limits read from the vehicle, a plan within them, the flight, θ from its own tlog.

SITL flies its own multicopter physics; `vehicle/configs/sitl_quad.toml` carries the
reference θ derived from ArduPilot's source (docs/vehicles/sitl_quad.md). The plan has a
fixed sample budget and seed, so it is the same on any machine; SITL runs at real time,
so the flight is not. The experiment starts as soon as SITL listens, as on a freshly
booted vehicle: the streamer waits for its pre-arm checks. `estimate` answers c_T from
the filter or, where the filter cannot follow the flight, from the force and torque
balance; both put it within 0.2 % on this seed (docs/benchmarks.md).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mavsysid.vehicle.config import load_vehicle

from tests.support.sitl import require_sitl, running_sitl

pytestmark = [pytest.mark.slow, pytest.mark.peers]

ROOT = Path(__file__).resolve().parents[2]
#: SITL set up as the vehicle file describes it (X frame, no ESC stand-in rpm).
SITL_PARMS = ROOT / "vehicle" / "configs" / "sitl_quad.parm"


def test_experiment_on_sitl_estimates_c_T_within_10_percent(tmp_path):
    """Plan → fly → estimate on SITL exits 0, keeps every file in the flight directory, flies
    within the stock limits it read, and estimates c_T within 10 % of SITL's reference."""
    require_sitl()
    logs = tmp_path / "logs"
    with running_sitl(tmp_path / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
        done = subprocess.run(
            [sys.executable, "-m", "mavsysid", "experiment", "--connect", sitl.connect,
             "--vehicle", "sitl_quad", "--budget", "20", "--samples", "200",
             "--refine-steps", "300", "--seed", "1", "--log-dir", str(logs)],
            capture_output=True, text=True, cwd=tmp_path, timeout=1200, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    (flight,) = [p for p in logs.iterdir() if p.is_dir()]
    for name in ("trajectory.json", "flight.tlog", "pose.csv", "meta.json", "estimate.json"):
        assert (flight / name).is_file(), name
    meta = json.loads((flight / "meta.json").read_text())
    assert meta["autopilot_limits"]["set_limits"] is False  # flown within the limits read
    estimate = json.loads((flight / "estimate.json").read_text())
    reference = load_vehicle("sitl_quad").theta[0]
    c_t = estimate["parameters"]["c_T"]["value"]
    assert abs(c_t / reference - 1.0) <= 0.10, (c_t, reference)
