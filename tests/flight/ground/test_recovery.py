"""Recovery after a flight that went wrong: `mavsysid stream` lands before it restores the
parameters, `mavsysid restore` puts them back after a kill -9, and a failed connection
leaves no flight directory. `mavsysid sim` and the streamer as real processes on
127.0.0.1; the parameters are read back with pymavlink alone."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.simvehicle.params import default_parameters
from mavsysid.formats.flight_dir import read_meta
from mavsysid.vehicle.config import load_vehicle

from tests.support.stream_flights import (
    SimProcess,
    export_excitation,
    flight_dir,
    read_all_parameters,
    read_parameters,
    read_tlog,
    run_mavsysid,
    run_stream,
    start_stream,
    wait_for,
)

SPEEDUP = "8"


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory) -> Path:
    """A 12 s excitation figure inside the test box."""
    return export_excitation(tmp_path_factory.mktemp("traj") / "figure12.json", 12.0)


def _stream_args(port: int, logs: Path) -> list[str]:
    return ["--connect", f"udp:127.0.0.1:{port}", "--speedup", SPEEDUP, "--log-dir", str(logs)]


def _changed(meta: dict) -> dict[str, float]:
    return {name: entry["original"] for name, entry in meta["parameters"].items()}


def _parameter_diff(port: int) -> dict[str, tuple[float, float]]:
    """Every parameter of the simulated ArduPilot Firefly that differs from its value at
    boot (read with pymavlink alone, all of them): name → (boot, now)."""
    boot = {p.name: p.value for p in default_parameters(Autopilot.ARDUPILOT,
                                                         load_vehicle("firefly"))}
    now = read_all_parameters(port)
    return {n: (boot.get(n, float("nan")), now.get(n, float("nan")))
            for n in boot.keys() | now.keys()
            if n not in boot or n not in now or now[n] != pytest.approx(boot[n])}


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_aborted_flight_lands_then_restores_every_parameter(tmp_path, trajectory):
    """Beyond the tracking limit: BRAKE, LAND, landed, then every changed parameter is
    restored; read back from the sim afterwards, each has its value before the flight."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP):
        result = run_stream(trajectory, *_stream_args(port, logs), "--max-tracking-error",
                            "0.004", cwd=tmp_path, timeout=120)
        meta = read_meta(flight_dir(logs) / "meta.json")
        changed = _changed(meta)
        values = read_parameters(port, list(changed))
        diff = _parameter_diff(port)
    assert result.returncode == 3, result.stderr
    err = result.stderr
    assert "aborted to BRAKE" in err and "aborted: mode LAND" in err
    # Before arming: the operator's box, the fence and the take-off point.
    shown = next(line for line in err.splitlines() if "take-off point" in line)
    assert "box x -2..2, y -2..2, z 0.5..2.5 m (--box); fence polygon x -3.5..3.5" in shown
    assert err.index("take-off point") < err.index("mavsysid stream: armed\n")
    assert err.index("landed and disarmed") < err.index("parameters restored")
    assert "left in force" not in err
    assert len(changed) >= 6 and all(e["restored"] for e in meta["parameters"].values())
    assert values == pytest.approx(changed), (values, changed)
    # The full parameter list as at boot: the fence points (FENCE_TOTAL) too.
    assert "fence points restored: 0 as before" in err
    assert meta["fence"]["points_before"] == [] and meta["fence"]["points_restored"]
    assert diff == {}, diff


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_restore_after_kill_9(tmp_path, trajectory):
    """kill -9 of the streamer mid-flight leaves the fence parameters set; `mavsysid restore
    FLIGHT_DIR --connect … --land` lands the vehicle and puts back what meta.json lists."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP):
        stream = start_stream(trajectory, *_stream_args(port, logs), cwd=tmp_path)
        wait_for(lambda: "streaming" in (tmp_path / "stream.err").read_text(), 90,
                 "the trajectory to start")
        stream.send_signal(signal.SIGKILL)
        stream.wait(timeout=10)
        directory = flight_dir(logs)
        changed = _changed(read_meta(directory / "meta.json"))
        before = read_parameters(port, list(changed))
        refused = run_mavsysid("restore", str(directory), "--connect",
                               f"udp:127.0.0.1:{port}", cwd=tmp_path)
        result = run_mavsysid("restore", str(directory), "--connect", f"udp:127.0.0.1:{port}",
                              "--land", cwd=tmp_path)
        after = read_parameters(port, list(changed))
        diff = _parameter_diff(port)
    assert before != pytest.approx(changed)  # the kill left the flight's values
    assert refused.returncode == 3 and "the vehicle is armed" in refused.stderr
    assert result.returncode == 0, result.stderr
    assert after == pytest.approx(changed), (after, changed)
    assert diff == {}, diff  # FENCE_TOTAL back to 0 with the fence points
    assert "fence points as before the flight: 0 (the fence mission cleared)" in result.stdout
    meta = json.loads((directory / "meta.json").read_text())
    assert all(e["restored"] for e in meta["parameters"].values())
    assert meta["restored_by"]["command"] == "mavsysid restore"
    assert meta["restored_by"]["fence_points"] == 0 and meta["fence"]["points_restored"]


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_landing_the_land_detector_misses_ends_disarmed(tmp_path, trajectory):
    """A vehicle whose land detector misses the touchdown (as ArduCopter's in 8 m/s of wind
    on SITL) stays armed on the ground and refuses a plain disarm: the streamer's landing,
    and after a kill -9 `restore --land`, disarm it (forced, once it rests at its take-off
    height) instead of giving up with it armed; then every parameter is as at boot."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, "--fault", "no-land-detect"):
        flown = run_stream(trajectory, *_stream_args(port, logs / "flown"), cwd=tmp_path,
                           timeout=180)
        stream = start_stream(trajectory, *_stream_args(port, logs / "killed"), cwd=tmp_path)
        wait_for(lambda: "streaming" in (tmp_path / "stream.err").read_text(), 90,
                 "the trajectory to start")
        stream.send_signal(signal.SIGKILL)
        stream.wait(timeout=10)
        result = run_mavsysid("restore", str(flight_dir(logs / "killed")), "--connect",
                              f"udp:127.0.0.1:{port}", "--land", cwd=tmp_path, timeout=240)
        diff = _parameter_diff(port)
    for done in (flown, result):
        assert done.returncode == 0, done.stderr[-3000:]
        assert "its land detector has not seen the touchdown" in done.stderr
        assert "forced disarm" in done.stderr and "landed and disarmed" in done.stderr
    assert diff == {}, diff


def test_restore_with_nothing_listed_needs_no_vehicle(tmp_path, capsys):
    """A flight that changed nothing: exit 0 without connecting."""
    from mavsysid.cli import main

    (tmp_path / "meta.json").write_text(json.dumps({"format": "mavsysid-flight",
                                                    "format_version": 1}))
    assert main(["restore", str(tmp_path), "--connect", "udp:127.0.0.1:9"]) == 0
    assert "nothing to restore" in capsys.readouterr().err


def test_no_vehicle_no_flight_directory(tmp_path, trajectory, capsys):
    """Nothing answers on the link: the heartbeat wait fails and no flight directory (nor
    the log root it made) is left."""
    from mavsysid.cli import main

    logs = tmp_path / "logs"
    code = main(["stream", str(trajectory), "--connect", f"udp:127.0.0.1:{free_udp_port()}",
                 "--box", "-2,-2,0.5,2,2,2.5", "--heartbeat-timeout", "0.5", "--log-dir",
                 str(logs)])
    assert code == 3 and "heartbeat" in capsys.readouterr().err
    assert not logs.exists()


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_dry_run_changes_no_parameter(tmp_path, trajectory):
    """`stream --dry-run` against `mavsysid sim`: every check, the box, the fence and the
    parameters it would change are printed; every parameter reads back as before, and
    nothing was armed or uploaded."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, lockstep=False):
        before = read_all_parameters(port)
        result = run_stream(trajectory, *_stream_args(port, logs), "--dry-run", cwd=tmp_path,
                            timeout=120, lockstep=False)
        after = read_all_parameters(port)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "every check passed; nothing armed, no parameter changed" in out
    assert "box        x -2..2, y -2..2, z 0.5..2.5 m (--box)" in out
    assert "fence      polygon 1.5 m outside the box" in out
    assert f"would set  FENCE_ENABLE {before['FENCE_ENABLE']:g} -> 1" in out
    assert len(before) > 20 and after == before
    sent = [m for _, m in read_tlog(flight_dir(logs) / "flight.tlog") if m.get_srcSystem() == 255]
    assert not [m for m in sent if m.get_type() == "COMMAND_LONG" and m.command == 400]
    assert not [m for m in sent if m.get_type() in ("PARAM_SET", "MISSION_COUNT")]
    meta = read_meta(flight_dir(logs) / "meta.json")
    assert meta["dry_run"] is True and meta["dry_run_parameters"]["FENCE_ENABLE"]["flight"] == 1
