"""plan → stream → land on real ArduCopter (SITL), its fence, its tlog, and a killed streamer.

One SITL (``../shared/sitl/``, loopback TCP only) with ArduCopter's stock position-controller
limits serves every flight of this module, one after the other (its SERIAL0 takes the next
streamer once the last has gone); a second ground station on SERIAL1 (system 254) watches
the parameters, as another operator would, so what it sees does not depend on the streamer.

1. A calibration flight planned for raised limits (``plan --autopilot-limits`` of
   ``sitl_quad_calibration.parm``) is more than stock ArduCopter follows: the streamer
   refuses it before take-off, in one line naming the parameters.
2. With ``--set-limits`` it raises them, sets the fence, flies, lands, and puts every changed
   parameter back: read back by the second ground station as they were.
3. `estimate` reads the ``flight.tlog`` of that flight, its rotor speeds from the motor
   outputs (SITL's ESC rpm is off, being no rotor speed): an estimate with a physically
   possible θ, or one line naming the file and what in the data stops it.
4. A streamer killed mid-flight (kill -9) leaves the vehicle inside the fence.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import parameter_names
from mavsysid.flight.ground.geofence import FENCE_MARGIN, GUIDED_TIMEOUT
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import (
    read_trajectory,
    trajectory_file_for,
    write_trajectory_file,
)
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.constants import GRAVITY

from tests.support.sitl import SitlInstance, observing, require_sitl, running_sitl, streaming
from tests.support.stream_flights import BOX, flight_dir, read_tlog, run_stream, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.peers]

_DATA = Path(__file__).resolve().parents[2] / "data"
#: Stock limits, X frame, no ESC telemetry (its rpm is never the rotor speed).
STOCK_PARMS = _DATA / "sitl_quad_x_stock.parm"
#: The raised limits the plan is made for (WPNAV_ACCEL 800, PSC_JERK_XY 20, ANGLE_MAX 4500, …).
RAISED_PARMS = _DATA / "sitl_quad_calibration.parm"
#: The SITL quad X with ArduPilot's motor numbering.
SITL_VEHICLE = _DATA / "sitl_quad_x.toml"
#: A short plan: 12 s budget, a fixed sample budget (the same plan on any machine).
PLAN = ("--vehicle", "quad_x", "--budget", "12", "--samples", "400", "--time", "0",
        "--refine-steps", "300", "--seed", "4")
#: The figure flown when the streamer is killed: peak acceleration about 2 m/s².
GENTLE = ExcitationSpec(duration=20.0, amplitude=(0.8, 0.6, 0.3))
#: The autopilot's position-controller limits (what ``--set-limits`` may raise).
LIMITS = tuple(parameter_names(Autopilot.ARDUPILOT))
#: What the fence (and the log's IMU rate) changes on ArduCopter.
FENCE = ("FENCE_ENABLE", "FENCE_TYPE", "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_MARGIN",
         "GUID_TIMEOUT", "LOG_BITMASK")


@dataclass(frozen=True)
class LimitsFlights:
    """The refused and the ``--set-limits`` stream of one plan, and the parameters the
    second ground station read before, during and after the flight."""

    directory: Path
    refused: subprocess.CompletedProcess[str]
    flown_returncode: int
    flown_stderr: str
    before: dict[str, float]
    during: dict[str, float]
    after: dict[str, float]

    def meta(self, which: str) -> dict[str, Any]:
        return json.loads((flight_dir(self.directory / which) / "meta.json").read_text())


@pytest.fixture(scope="module")
def sitl(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SitlInstance]:
    require_sitl()
    with running_sitl(tmp_path_factory.mktemp("sitl"), defaults=[STOCK_PARMS],
                      model="x") as instance:
        yield instance


def _sampled_tilt(path: Path) -> float:
    """The largest lean angle of a trajectory file's flight, degrees, sampled every 2 ms."""
    trajectory = read_trajectory(path).trajectory
    a = trajectory.flat_outputs(np.linspace(0.0, trajectory.duration,
                                            int(trajectory.duration / 0.002) + 1)).acceleration
    return math.degrees(float(np.max(np.arctan2(np.hypot(a[:, 0], a[:, 1]),
                                                a[:, 2] + GRAVITY))))


def _plan(directory: Path) -> Path:
    out = directory / "plan.json"
    done = subprocess.run([sys.executable, "-m", "mavsysid", "-q", "plan", *PLAN,
                           "--autopilot-limits", str(RAISED_PARMS), "-o", str(out)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def limits_flights(sitl: SitlInstance, tmp_path_factory: pytest.TempPathFactory
                   ) -> LimitsFlights:
    directory = tmp_path_factory.mktemp("limits")
    trajectory = _plan(directory)
    refused = run_stream(trajectory, "--connect", sitl.connect, "--vehicle", "quad_x",
                         "--log-dir", str(directory / "refused"), cwd=directory,
                         timeout=240.0, lockstep=False)
    # SITL opened SERIAL1 when the refused streamer connected: read before the next one.
    with observing(sitl) as observer:
        before = observer.params(LIMITS + FENCE)
        with streaming(trajectory, sitl, "--vehicle", "quad_x", "--set-limits", "--log-dir",
                       str(directory / "logs"), cwd=directory) as stream:
            # The fence switches on before arming and stays on while the streamer flies.
            wait_for(lambda: observer.params(("FENCE_ENABLE",)).get("FENCE_ENABLE") == 1,
                     150.0, "FENCE_ENABLE = 1 during the flight")
            during = observer.params(FENCE)
            stream.communicate(timeout=300)
        after = observer.params(LIMITS + FENCE)
    return LimitsFlights(directory, refused, stream.returncode,
                         (directory / "stream.err").read_text(), before, during, after)


def test_planned_flight_refused_on_stock_limits(limits_flights: LimitsFlights) -> None:
    refused = limits_flights.refused
    lines = [ln for ln in refused.stderr.splitlines() if ln.startswith("mavsysid stream: error")]
    assert refused.returncode == 3, refused.stderr[-3000:]
    assert len(lines) == 1 and "flight refused: the autopilot's limits" in lines[0], lines
    # Planned for PSC_JERK_XY 20: always above stock 5; the lean angle above stock 30° only
    # as the plan has it (sampled here, independently of the streamer's peaks).
    assert "PSC_JERK_XY 5 <" in lines[0], lines[0]
    tilt = _sampled_tilt(limits_flights.directory / "plan.json")
    if abs(tilt - 30.0) > 0.1:
        assert ("ANGLE_MAX 3000 <" in lines[0]) == (tilt > 30.0), (tilt, lines[0])
    # Refused before anything changed or flew.
    meta = limits_flights.meta("refused")
    assert meta["tracking"]["rows"] == 0 and not meta.get("parameters"), meta


def test_flown_with_set_limits_and_every_limit_restored(limits_flights: LimitsFlights) -> None:
    f = limits_flights
    assert f.flown_returncode == 0, f.flown_stderr[-3000:]
    assert "autopilot limits raised for the flight" in f.flown_stderr
    meta = f.meta("logs")
    assert meta["autopilot_limits"]["set_limits"] is True
    raised = {n for n in meta["parameters"] if n in LIMITS}
    refused = set(re.findall(r"([A-Z][A-Z_]+) [0-9.]+ <", f.refused.stderr))
    assert "PSC_JERK_XY" in refused and refused <= raised, (refused, meta["parameters"])
    assert all(entry["restored"] for entry in meta["parameters"].values()), meta["parameters"]
    # Read back by a second ground station: every limit as before the flight.
    assert set(f.before) == set(LIMITS + FENCE) and f.after == f.before, (f.before, f.after)
    assert meta["tracking"]["rms_m"] < 0.5 and meta["setpoints"]["rate_hz"] > 45.0, meta


def test_fence_is_set_for_the_flight_and_parameters_come_back(limits_flights: LimitsFlights
                                                              ) -> None:
    f = limits_flights
    assert f.flown_returncode == 0, f.flown_stderr[-3000:]
    assert f.during["FENCE_TYPE"] == 5 and f.during["FENCE_ACTION"] == 4
    assert f.during["GUID_TIMEOUT"] == pytest.approx(GUIDED_TIMEOUT)
    assert f.after == f.before, (f.before, f.during, f.after)
    meta = f.meta("logs")
    assert meta["fence"]["kind"] == "polygon" and meta["fence"]["margin_m"] == FENCE_MARGIN
    changed = set(meta["parameters"])
    assert changed & set(FENCE) == {n for n in FENCE if f.during[n] != f.before[n]}, changed
    assert changed - set(FENCE) <= set(LIMITS), changed
    assert all(entry["restored"] for entry in meta["parameters"].values()), meta["parameters"]
    assert "parameters restored:" in f.flown_stderr


def _estimates(tlog: Path, runs: dict[str, Path]) -> list[subprocess.CompletedProcess[str]]:
    """``estimate`` of ``tlog`` with each vehicle → output file, run side by side (the second
    core is otherwise idle in this sequential suite)."""
    started = [subprocess.Popen([sys.executable, "-m", "mavsysid", "estimate", str(tlog),
                                 "--vehicle", vehicle, "-o", str(out)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
               for vehicle, out in runs.items()]
    try:
        outputs = [p.communicate(timeout=300) for p in started]
        return [subprocess.CompletedProcess(p.args, p.returncode, *output)
                for p, output in zip(started, outputs, strict=True)]
    finally:
        for p in started:
            if p.poll() is None:
                p.kill()
                p.communicate()


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


def test_estimate_reads_the_tlog_streamed_to_arducopter_sitl(limits_flights: LimitsFlights
                                                             ) -> None:
    assert limits_flights.flown_returncode == 0, limits_flights.flown_stderr[-3000:]
    tlog = flight_dir(limits_flights.directory / "logs") / "flight.tlog"
    # What SITL sent: no ESC telemetry (SIM_ESC_TELEM 0), and the four motor outputs at
    # the asked rate, moving with the flight (the hover alone is about 1590 µs).
    records = read_tlog(tlog)
    assert not [m for _, m in records if m.get_type().startswith("ESC_TELEMETRY")]
    outputs = np.array([[m.servo1_raw, m.servo2_raw, m.servo3_raw, m.servo4_raw]
                        for _, m in records if m.get_type() == "SERVO_OUTPUT_RAW"
                        and m.get_srcSystem() == 1])
    assert len(outputs) > 500
    flying = outputs[(outputs > 1300).all(axis=1)]
    assert len(flying) > 250 and (np.ptp(flying, axis=0) > 100).all(), np.ptp(flying, axis=0)
    # With the matching vehicle file, and with the shipped quad_x (mavsysid's own rotor
    # order, a 1 kg prior where SITL flies 3 kg): each reads the log, whatever it concludes.
    runs = {vehicle: limits_flights.directory / f"estimate_{Path(vehicle).stem}.json"
            for vehicle in (str(SITL_VEHICLE), "quad_x")}
    for result, out in zip(_estimates(tlog, runs), runs.values(), strict=True):
        _assert_reads(result, tlog, out)


def _outside(p: Any) -> float:
    """Distance (m) of a LOCAL_POSITION_NED outside BOX (0 inside), ENU."""
    east, north, up = p.y, p.x, -p.z
    d = [max(BOX[0] - east, 0.0, east - BOX[3]), max(BOX[1] - north, 0.0, north - BOX[4]),
         max(0.0, up - BOX[5])]
    return math.sqrt(sum(x * x for x in d))


def test_killed_streamer_leaves_arducopter_inside_the_fence(sitl: SitlInstance,
                                                            tmp_path: Path) -> None:
    """Last in the module: the vehicle is left hovering where the kill put it."""
    trajectory = tmp_path / "gentle.json"
    write_trajectory_file(trajectory, trajectory_file_for(excitation_trajectory(GENTLE),
                                                          load_vehicle("quad_x"), box=BOX))
    with streaming(trajectory, sitl, "--vehicle", "quad_x", "--set-limits", "--log-dir",
                   str(tmp_path / "logs"), cwd=tmp_path) as stream, observing(sitl) as observer:
        err = tmp_path / "stream.err"
        wait_for(lambda: "streaming the" in err.read_text(), 180.0, "the trajectory to stream")
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
    print(f"after kill -9: farthest {worst:.2f} m outside the box, at rest "
          f"{_outside(last):.2f} m outside (fence margin {FENCE_MARGIN} m)")
    assert _outside(last) <= FENCE_MARGIN, (worst, last)
