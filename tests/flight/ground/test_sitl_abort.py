"""An aborted flight on real ArduCopter (SITL, ``../shared/sitl``, loopback TCP only): the
streamer brakes, lands and waits for the disarm before it restores the parameters and
exits, and a second ground station reads every changed parameter back as it was."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import parameter_names

from tests.support.sitl import (
    Observer,
    gentle_trajectory,
    observing,
    require_sitl,
    running_sitl,
    streaming,
)
from tests.support.stream_flights import BOX, flight_dir, read_tlog

pytestmark = [pytest.mark.slow, pytest.mark.peers]

#: The shipped SITL vehicle's defaults (X frame: SITL runs ``--model x``).
SITL_PARMS = Path(__file__).resolve().parents[3] / "vehicle" / "configs" / "sitl_quad.parm"
#: What ``--set-limits`` may raise and what the fence changes on ArduCopter.
WATCHED = (*parameter_names(Autopilot.ARDUPILOT), "FENCE_ENABLE", "FENCE_TYPE",
           "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_MARGIN", "GUID_TIMEOUT", "LOG_BITMASK")
#: MAV_MODE_FLAG_SAFETY_ARMED.
ARMED_FLAG = 0x80


def _armed(observer: Observer) -> bool:
    """Whether the vehicle's next HEARTBEAT (after what arrived unread) says armed."""
    observer.drain()
    while True:
        m = observer.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0)
        assert m is not None, "no HEARTBEAT from SITL"
        if m.get_srcSystem() == 1 and m.get_srcComponent() == 1:
            return bool(m.base_mode & ARMED_FLAG)


def test_aborted_flight_on_arducopter_lands_then_restores_every_parameter(tmp_path: Path
                                                                           ) -> None:
    """Beyond the tracking limit on SITL: BRAKE, LAND, disarmed before the streamer exits,
    and every parameter it changed reads back, over SITL's second port, as before."""
    require_sitl()
    trajectory = gentle_trajectory(tmp_path / "gentle.json", "sitl_quad", BOX)
    logs = tmp_path / "logs"
    with running_sitl(tmp_path / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
        # SERIAL0 serves one client: read before the streamer takes it.
        first = Observer(sitl.port)
        try:
            before = first.params(WATCHED)
        finally:
            first.close()
        # A tracking limit no real vehicle meets: the abort comes on the way to the figure.
        with streaming(trajectory, sitl, "--vehicle", "sitl_quad", "--set-limits",
                       "--max-tracking-error", "0.004", "--log-dir", str(logs),
                       cwd=tmp_path) as stream, observing(sitl) as observer:
            stream.communicate(timeout=240)
            armed_at_exit = _armed(observer)
            meta = json.loads((flight_dir(logs) / "meta.json").read_text())
            changed = {name: entry["original"] for name, entry in meta["parameters"].items()}
            after = observer.params(tuple(changed))
    err = (tmp_path / "stream.err").read_text()
    assert stream.returncode == 3, err[-3000:]
    assert "aborted to BRAKE" in err and "aborted: mode LAND" in err, err[-3000:]
    # Landed before restoring, restored before exiting: SITL still disarmed at the exit.
    assert err.index("landed and disarmed") < err.index("parameters restored"), err[-3000:]
    assert "left in force" not in err, err[-3000:]
    assert not armed_at_exit, "the streamer exited with the vehicle still armed"
    heartbeats = [m for _, m in read_tlog(flight_dir(logs) / "flight.tlog")
                  if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1]
    assert any(m.base_mode & ARMED_FLAG for m in heartbeats), "it never armed"
    # Every changed parameter: restored by the streamer's account, by meta.json's original,
    # and by the read before the flight, each read back by another ground station.
    assert set(before) == set(WATCHED), before
    assert "FENCE_ENABLE" in changed and set(changed) <= set(WATCHED), changed
    assert all(entry["restored"] for entry in meta["parameters"].values()), meta["parameters"]
    assert {n: before[n] for n in changed} == pytest.approx(changed), (before, changed)
    assert after == pytest.approx(changed), (after, changed)
