"""``stream --dry-run`` on real ArduCopter (SITL, ``../shared/sitl``, loopback TCP only),
started the moment SITL listens: the streamer's pre-arm wait sees a freshly booted
autopilot become ready, runs every check, and changes no parameter (read back)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import parameter_names

from tests.support.sitl import Observer, gentle_trajectory, require_sitl, running_sitl
from tests.support.stream_flights import BOX, flight_dir, read_tlog, run_stream

pytestmark = [pytest.mark.slow, pytest.mark.peers]

_DATA = Path(__file__).resolve().parents[2] / "data"
#: Stock limits, X frame.
STOCK_PARMS = _DATA / "sitl_quad_x_stock.parm"
#: What ``--set-limits`` may raise and what the fence changes on ArduCopter.
WATCHED = (*parameter_names(Autopilot.ARDUPILOT), "FENCE_ENABLE", "FENCE_TYPE",
           "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_MARGIN", "GUID_TIMEOUT", "LOG_BITMASK")
#: MAV_SYS_STATUS_SENSOR_PREARM_CHECK.
PREARM_BIT = 0x10000000


def _read(port: int) -> dict[str, float]:
    """The watched parameters, read by another ground station on SERIAL0 (which serves one
    client at a time: closed before the streamer connects)."""
    observer = Observer(port)
    try:
        return observer.params(WATCHED)
    finally:
        observer.close()


def test_dry_run_on_fresh_arducopter_waits_for_prearm_and_changes_nothing(tmp_path: Path
                                                                         ) -> None:
    """A dry run started on a freshly booted SITL passes once its pre-arm checks do, names
    the fence it would set, sends no PARAM_SET, mission or arm, and every limit and fence
    parameter reads back as before."""
    require_sitl()
    trajectory = gentle_trajectory(tmp_path / "gentle.json", "quad_x", BOX)
    logs = tmp_path / "logs"
    with running_sitl(tmp_path / "sitl", defaults=[STOCK_PARMS], model="x") as sitl:
        before = _read(sitl.port)
        result = run_stream(trajectory, "--connect", sitl.connect, "--vehicle", "quad_x",
                            "--set-limits", "--dry-run", "--log-dir", str(logs), cwd=tmp_path,
                            timeout=400.0, lockstep=False)
        after = _read(sitl.port)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "every check passed; nothing armed, no parameter changed" in result.stdout
    would = set(re.findall(r"would set  ([A-Z][A-Z_]+) ", result.stdout))
    assert "FENCE_ENABLE" in would and would <= set(WATCHED), result.stdout
    assert set(before) == set(WATCHED) and after == before, (before, after)
    messages = read_tlog(flight_dir(logs) / "flight.tlog")
    health = [m.onboard_control_sensors_health & PREARM_BIT for _, m in messages
              if m.get_type() == "SYS_STATUS"]
    # SITL was not ready when the streamer met it; the wait saw it become ready.
    assert health and not health[0] and health[-1], health
    sent = [m for _, m in messages if m.get_srcSystem() == 255]
    assert not [m for m in sent if m.get_type() == "COMMAND_LONG" and m.command == 400]
    assert not [m for m in sent if m.get_type() in ("PARAM_SET", "MISSION_COUNT",
                                                    "MISSION_ITEM_INT")]
