"""`estimate` reads the ``flight.tlog`` that `mavsysid stream` writes against real ArduCopter.

The streamer flies a short, gentle excitation figure with ArduCopter SITL
(``../shared/sitl/``, loopback TCP only) as the vehicle; `estimate` must then read the tlog:
either an estimate with a physically possible θ, or one line that names the file and says
what in the data stops it — never a traceback, a "gap" or "cannot read".
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.vehicle.config import load_vehicle

from tests.support.sitl import require_sitl, running_sitl
from tests.support.stream_flights import BOX, flight_dir, read_tlog, run_stream

pytestmark = [pytest.mark.slow, pytest.mark.peers]

_DATA = Path(__file__).resolve().parents[2] / "data"
#: Raised tracking limits, an X frame and ESC rpm telemetry (see the file's comments).
SITL_PARMS = _DATA / "sitl_quad_calibration.parm"
#: The SITL quad X with ArduPilot's motor numbering.
SITL_VEHICLE = _DATA / "sitl_quad_x.toml"
#: Peak acceleration about 2 m/s², within the raised WPNAV_ACCEL; 20 s keeps the whole test
#: (SITL boot ~35 s, take-off, flight, landing) under about 2 minutes.
GENTLE = ExcitationSpec(duration=20.0, amplitude=(0.8, 0.6, 0.3))


def _estimate(tlog: Path, vehicle: str, out: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mavsysid", "estimate", str(tlog), "--vehicle",
                           vehicle, "-o", str(out)], capture_output=True, text=True,
                          timeout=300, check=False)


def _assert_reads(result: subprocess.CompletedProcess[str], tlog: Path, out: Path) -> None:
    """An estimate with a physically possible θ, or one clear line about the data."""
    assert "Traceback" not in result.stderr, result.stderr
    if result.returncode == 0:
        params = json.loads(out.read_text())["parameters"]
        value = {name: params[name]["value"] for name in params}
        assert all(value[p] > 0 for p in ("c_T", "c_M", "j_x", "j_y", "j_z")), value
        assert value["c_D"] >= 0, value
        j = sorted(value[p] for p in ("j_x", "j_y", "j_z"))
        # Rigid-body triangle inequality, with the slack a 6-parameter estimate needs.
        assert j[0] + j[1] >= 0.75 * j[2], value
        assert all(params[p]["sigma"] is not None and params[p]["sigma"] > 0 for p in params)
        return
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert result.returncode in (2, 3), result.stderr
    assert len(lines) == 1, result.stderr
    assert tlog.name in lines[0], lines[0]
    for wrong in ("gap", "cannot read", "no pose", "no motor"):
        assert wrong not in lines[0].lower(), lines[0]


def test_estimate_reads_the_tlog_streamed_to_arducopter_sitl(tmp_path: Path) -> None:
    require_sitl()
    trajectory = tmp_path / "gentle.json"
    write_trajectory_file(trajectory, trajectory_file_for(
        excitation_trajectory(GENTLE), load_vehicle("quad_x"), box=BOX))
    logs = tmp_path / "logs"
    with running_sitl(tmp_path / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
        stream = run_stream(trajectory, "--connect", sitl.connect, "--vehicle", "quad_x",
                            "--log-dir", str(logs), cwd=tmp_path, timeout=240.0,
                            lockstep=False)  # a real autopilot: wall clock
    assert stream.returncode == 0, stream.stderr[-3000:]
    tlog = flight_dir(logs) / "flight.tlog"

    # What SITL sent: ESC rpm that moves with the motor commands, at the asked rate.
    rpm = np.array([m.rpm for _, m in read_tlog(tlog) if m.get_type() == "ESC_TELEMETRY_1_TO_4"])
    assert len(rpm) > 500
    assert (rpm > 0).any(axis=0).all(), "SITL sent no ESC rpm (is SIM_VIB_MOT_MAX set?)"

    # With the matching vehicle file, and with the shipped quad_x (mavsysid's own rotor
    # order, a 1 kg prior where SITL flies 3 kg): each reads the log, whatever it concludes.
    for vehicle in (str(SITL_VEHICLE), "quad_x"):
        out = tmp_path / f"estimate_{Path(vehicle).stem}.json"
        _assert_reads(_estimate(tlog, vehicle, out), tlog, out)
