"""Recovery after a flight that went wrong: `mavsysid stream` lands before it restores the
parameters, `mavsysid restore` puts them back after a kill -9, and a failed connection
leaves no flight directory. `mavsysid sim` and the streamer as real processes on
127.0.0.1; the parameters are read back with pymavlink alone."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import pytest
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.formats.flight_dir import read_meta

from tests.support.stream_flights import (
    SimProcess,
    export_excitation,
    flight_dir,
    read_parameters,
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
    assert result.returncode == 3, result.stderr
    err = result.stderr
    assert "aborted to BRAKE" in err and "aborted: mode LAND" in err
    assert err.index("landed and disarmed") < err.index("parameters restored")
    assert "left in force" not in err
    assert len(changed) >= 6 and all(e["restored"] for e in meta["parameters"].values())
    assert values == pytest.approx(changed), (values, changed)


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
    assert before != pytest.approx(changed)  # the kill left the flight's values
    assert refused.returncode == 3 and "the vehicle is armed" in refused.stderr
    assert result.returncode == 0, result.stderr
    assert after == pytest.approx(changed), (after, changed)
    meta = json.loads((directory / "meta.json").read_text())
    assert all(e["restored"] for e in meta["parameters"].values())
    assert meta["restored_by"]["command"] == "mavsysid restore"


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
