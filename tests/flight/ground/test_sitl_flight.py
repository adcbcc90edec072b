"""plan → stream → land on real ArduCopter (SITL) with its stock position-controller limits.

A calibration flight planned for raised limits (``plan --autopilot-limits`` of
``sitl_quad_calibration.parm``) is more than stock ArduCopter follows: the streamer refuses
it before take-off, in one line naming the parameters. With ``--set-limits`` it raises them,
flies, lands, and puts them back: a second ground station on SITL's SERIAL1 reads them back
as they were. Loopback TCP only; one SITL serves both runs (its SERIAL0 takes the second
streamer once the first has gone).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import parameter_names

from tests.support.sitl import Observer, require_sitl, running_sitl
from tests.support.stream_flights import flight_dir, run_stream

pytestmark = [pytest.mark.slow, pytest.mark.peers]

_DATA = Path(__file__).resolve().parents[2] / "data"
#: Stock limits, X frame.
STOCK_PARMS = _DATA / "sitl_quad_x_stock.parm"
#: The raised limits the plan is made for (WPNAV_ACCEL 800, PSC_JERK_XY 20, ANGLE_MAX 4500, …).
RAISED_PARMS = _DATA / "sitl_quad_calibration.parm"
#: A short plan: 12 s budget, a fixed sample budget (the same plan on any machine).
PLAN = ("--vehicle", "quad_x", "--budget", "12", "--samples", "400", "--time", "0",
        "--refine-steps", "300", "--seed", "4")


def _plan(tmp_path: Path) -> Path:
    out = tmp_path / "plan.json"
    done = subprocess.run([sys.executable, "-m", "mavsysid", "-q", "plan", *PLAN,
                           "--autopilot-limits", str(RAISED_PARMS), "-o", str(out)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    return out


def test_planned_flight_refused_on_stock_limits_then_flown_with_set_limits(tmp_path: Path):
    require_sitl()
    trajectory = _plan(tmp_path)
    names = tuple(parameter_names(Autopilot.ARDUPILOT))
    with running_sitl(tmp_path / "sitl", defaults=[STOCK_PARMS], model="x") as sitl:
        common = ("--connect", sitl.connect, "--vehicle", "quad_x")
        refused = run_stream(trajectory, *common, "--log-dir", str(tmp_path / "refused"),
                             cwd=tmp_path, timeout=240.0, lockstep=False)
        observer = Observer(sitl.port + 2)
        try:
            before = observer.params(names)
            flown = run_stream(trajectory, *common, "--set-limits", "--log-dir",
                               str(tmp_path / "logs"), cwd=tmp_path, timeout=300.0,
                               lockstep=False)
            after = observer.params(names)
        finally:
            observer.close()

    lines = [ln for ln in refused.stderr.splitlines() if ln.startswith("mavsysid stream: error")]
    assert refused.returncode == 3, refused.stderr[-3000:]
    assert len(lines) == 1 and "flight refused: the autopilot's limits" in lines[0], lines
    assert "PSC_JERK_XY 5 <" in lines[0] and "ANGLE_MAX 3000 <" in lines[0], lines[0]
    # Refused before anything changed or flew.
    meta = json.loads((flight_dir(tmp_path / "refused") / "meta.json").read_text())
    assert meta["tracking"]["rows"] == 0 and not meta.get("parameters"), meta

    assert flown.returncode == 0, flown.stderr[-3000:]
    assert "autopilot limits raised for the flight" in flown.stderr
    meta = json.loads((flight_dir(tmp_path / "logs") / "meta.json").read_text())
    assert meta["autopilot_limits"]["set_limits"] is True
    raised = {n for n in meta["parameters"] if n in names}
    assert {"PSC_JERK_XY", "ANGLE_MAX"} <= raised, meta["parameters"]
    assert all(entry["restored"] for entry in meta["parameters"].values()), meta["parameters"]
    # Read back by a second ground station: every limit as before the flight.
    assert set(before) == set(names) and after == before, (before, after)
    if "fence" in meta:  # the geofence (flight/ground/geofence.py), when wired in
        assert meta["fence"]["kind"] in ("polygon", "circle"), meta["fence"]
        assert {"FENCE_ENABLE", "GUID_TIMEOUT"} <= set(meta["parameters"])
    assert meta["tracking"]["rms_m"] < 0.5 and meta["setpoints"]["rate_hz"] > 45.0, meta
