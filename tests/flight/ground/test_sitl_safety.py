"""The box enforced by real ArduCopter (SITL): the fence is set for the flight, every changed
parameter comes back afterwards, and a streamer killed mid-flight (kill -9) leaves the
vehicle inside the fence.

The test watches SITL through its second MAVLink port (SERIAL1, 5762 + 10 N) with its own
pymavlink connection, as a second ground station would, so what it sees does not depend on
the streamer being alive.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import pytest
from mavsysid.flight.ground.geofence import FENCE_MARGIN, GUIDED_TIMEOUT
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.vehicle.config import load_vehicle

from tests.support.sitl import Observer, require_sitl, running_sitl
from tests.support.stream_flights import BOX, flight_dir, start_stream, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.peers]

_DATA = Path(__file__).resolve().parents[2] / "data"
SITL_PARMS = _DATA / "sitl_quad_calibration.parm"
GENTLE = ExcitationSpec(duration=20.0, amplitude=(0.8, 0.6, 0.3))
#: What the flight changes on ArduCopter (read back before and after).
WATCHED = ("FENCE_ENABLE", "FENCE_TYPE", "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_MARGIN",
           "GUID_TIMEOUT")


def _trajectory(tmp_path: Path) -> Path:
    path = tmp_path / "gentle.json"
    write_trajectory_file(path, trajectory_file_for(excitation_trajectory(GENTLE),
                                                    load_vehicle("quad_x"), box=BOX))
    return path


def _outside(p: Any) -> float:
    """Distance (m) of a LOCAL_POSITION_NED outside BOX (0 inside), ENU."""
    east, north, up = p.y, p.x, -p.z
    d = [max(BOX[0] - east, 0.0, east - BOX[3]), max(BOX[1] - north, 0.0, north - BOX[4]),
         max(0.0, up - BOX[5])]
    return math.sqrt(sum(x * x for x in d))


def test_fence_is_set_for_the_flight_and_parameters_come_back(tmp_path: Path) -> None:
    require_sitl()
    logs = tmp_path / "logs"
    with running_sitl(tmp_path / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
        stream = start_stream(_trajectory(tmp_path), "--connect", sitl.connect, "--vehicle",
                              "quad_x", "--log-dir", str(logs), cwd=tmp_path,
                              lockstep=False)  # a real autopilot: wall clock
        observer = Observer(sitl.port + 2)
        try:
            before = observer.params(WATCHED)
            assert set(before) == set(WATCHED)
            # The fence switches on before arming and stays on while the streamer flies.
            wait_for(lambda: observer.params(("FENCE_ENABLE",)).get("FENCE_ENABLE") == 1,
                     150.0, "FENCE_ENABLE = 1 during the flight")
            during = observer.params(WATCHED)
            stream.communicate(timeout=240)
            assert stream.returncode == 0, (tmp_path / "stream.err").read_text()[-3000:]
            after = observer.params(WATCHED)
        finally:
            if stream.poll() is None:
                stream.kill()
            observer.close()
    assert during["FENCE_TYPE"] == 5 and during["FENCE_ACTION"] == 4
    assert during["GUID_TIMEOUT"] == pytest.approx(GUIDED_TIMEOUT)
    assert after == before, (before, during, after)
    meta = json.loads((flight_dir(logs) / "meta.json").read_text())
    assert meta["fence"]["kind"] == "polygon" and meta["fence"]["margin_m"] == FENCE_MARGIN
    assert all(entry["restored"] for entry in meta["parameters"].values()), meta["parameters"]
    assert set(meta["parameters"]) == {n for n in WATCHED if during[n] != before[n]}
    assert "parameters restored:" in (tmp_path / "stream.err").read_text()


def test_killed_streamer_leaves_arducopter_inside_the_fence(tmp_path: Path) -> None:
    require_sitl()
    logs = tmp_path / "logs"
    with running_sitl(tmp_path / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
        stream = start_stream(_trajectory(tmp_path), "--connect", sitl.connect, "--vehicle",
                              "quad_x", "--log-dir", str(logs), cwd=tmp_path,
                              lockstep=False)  # a real autopilot: wall clock
        observer = Observer(sitl.port + 2)
        try:
            err = tmp_path / "stream.err"
            wait_for(lambda: "streaming the" in err.read_text(), 180.0,
                     "the trajectory to stream")
            time.sleep(5.0)  # mid-figure, moving
            stream.kill()  # SIGKILL: no clean-up of any kind
            stream.wait(timeout=10)
            worst, calm_since, last = 0.0, None, None
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline:
                p = observer.position()
                assert p is not None, "SITL stopped sending LOCAL_POSITION_NED"
                last, worst = p, max(worst, _outside(p))
                calm = math.sqrt(p.vx**2 + p.vy**2 + p.vz**2) < 0.1
                calm_since = (calm_since or time.monotonic()) if calm else None
                if calm_since is not None and time.monotonic() - calm_since > 3.0:
                    break
            else:
                raise AssertionError(f"still moving 60 s after the kill ({last})")
        finally:
            if stream.poll() is None:
                stream.kill()
            observer.close()
    print(f"after kill -9: farthest {worst:.2f} m outside the box, at rest "
          f"{_outside(last):.2f} m outside (fence margin {FENCE_MARGIN} m)")
    assert _outside(last) <= FENCE_MARGIN, (worst, last)
