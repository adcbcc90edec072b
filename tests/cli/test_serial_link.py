"""A vehicle on a serial link: `mavsysid sim` and the ground commands on two pseudo-terminals
joined like a null-modem cable (`tests.support.serial_link.NullModem`), each end opened as
a serial device with a baud rate (pyserial through pymavlink), as a USB autopilot or a
telemetry radio is.
"""

from __future__ import annotations

import importlib.metadata
import json
import re
from pathlib import Path

import pytest
from mavsysid.formats.flight_dir import read_meta

from mavsysid.cli import main
from tests.support.serial_link import NullModem
from tests.support.stream_flights import (
    SimProcess,
    export_excitation,
    flight_dir,
    read_tlog,
    run_mavsysid,
    run_stream,
    start_stream,
    wait_for,
)

pytestmark = [pytest.mark.filterwarnings("ignore::UserWarning")]

SPEEDUP = "8"


def test_pyserial_is_installed_with_the_package() -> None:
    """A serial link needs pyserial (pymavlink imports it only then): it is a dependency."""
    requirements = importlib.metadata.requires("mavsysid") or []
    names = {re.split(r"[<>=!~ ;\[]", r, maxsplit=1)[0].lower() for r in requirements
             if "extra ==" not in r}
    assert "pyserial" in names, requirements


@pytest.mark.slow
def test_stream_flies_over_a_serial_link(tmp_path: Path) -> None:
    """A 12 s figure flown end to end over the serial devices, lock-stepped: every
    message in both directions went through the cable, and the flight is complete."""
    trajectory = export_excitation(tmp_path / "figure12.json", 12.0)
    with NullModem() as cable, SimProcess(tmp_path / "sim", "--connect",
                                          f"{cable.vehicle}:115200", "--speedup", SPEEDUP):
        result = run_stream(trajectory, "--connect", f"{cable.ground}:115200", "--speedup",
                            SPEEDUP, "--log-dir", str(tmp_path / "logs"), cwd=tmp_path)
        copied = cable.copied
    assert result.returncode == 0, result.stderr[-3000:]
    assert "landed and disarmed" in result.stderr
    directory = flight_dir(tmp_path / "logs")
    meta = read_meta(directory / "meta.json")
    assert meta["status"] == "complete" and meta["connection"] == f"{cable.ground}:115200"
    assert meta["tracking"]["rms_m"] < 0.05
    records = read_tlog(directory / "flight.tlog")
    assert sum(len(m.get_msgbuf()) for _, m in records) <= copied
    assert any(m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" for _, m in records)


def _pose_rows(logs: Path) -> int:
    """Rows written so far to the flight's pose.csv (0 before it exists)."""
    found = list(logs.glob("*/pose.csv"))
    return max(0, len(found[0].read_text().splitlines()) - 1) if found else 0


@pytest.mark.slow
def test_a_serial_device_that_goes_away_ends_the_stream_in_one_line(tmp_path: Path) -> None:
    """The cable is pulled mid-flight (both pseudo-terminals close): the streamer stops in
    one line naming the device, exit 3, and keeps what it recorded."""
    trajectory = export_excitation(tmp_path / "figure12.json", 12.0)
    logs = tmp_path / "logs"
    cable = NullModem()
    try:
        with SimProcess(tmp_path / "sim", "--connect", f"{cable.vehicle}:115200",
                        "--speedup", SPEEDUP):
            stream = start_stream(trajectory, "--connect", f"{cable.ground}:115200",
                                  "--speedup", SPEEDUP, "--log-dir", str(logs), cwd=tmp_path)
            wait_for(lambda: _pose_rows(logs) > 300, 120.0, "the flight to be under way")
            cable.close()
            code = stream.wait(timeout=60)
    finally:
        cable.close()
    err = (tmp_path / "stream.err").read_text()
    errors = [line for line in err.splitlines() if "error:" in line]
    assert code == 3, err[-3000:]
    assert len(errors) == 1 and f"the serial device {cable.ground}:115200 stopped" in errors[0]
    assert "Traceback" not in err and "internal error" not in err
    meta = read_meta(flight_dir(logs) / "meta.json")
    assert meta["status"] == "aborted" and "serial device" in meta["reason"]


@pytest.mark.slow
def test_plan_reads_the_limits_over_a_serial_link(tmp_path: Path, planned, capsys) -> None:
    """``plan --connect DEVICE:BAUD`` reads the autopilot's limits over the serial device."""
    with NullModem() as cable, SimProcess(tmp_path / "sim", "--connect",
                                          f"{cable.vehicle}:57600", "--vehicle", "quad_x",
                                          lockstep=False) as sim:
        sim.wait_ready(timeout=90.0)
        link = f"{cable.ground}:57600"
        code = main(["plan", "--vehicle", "quad_x", "--connect", link, "-o",
                     str(tmp_path / "t.json"), "--no-preview"])
        err = capsys.readouterr().err
    assert code == 0, err
    assert f"limits read from the ArduPilot vehicle on {link}" in err, err
    assert planned[-1].autopilot_limits is not None
    assert not planned[-1].autopilot_limits.is_empty()


@pytest.mark.slow
def test_experiment_over_a_serial_link(tmp_path: Path) -> None:
    """``experiment --connect DEVICE:BAUD``: limits, plan, flight and estimate over the cable
    (lock-stepped); the flight directory keeps everything."""
    logs = tmp_path / "logs"
    with NullModem() as cable, SimProcess(tmp_path / "sim", "--connect",
                                          f"{cable.vehicle}:115200", "--vehicle", "quad_x",
                                          "--speedup", SPEEDUP):
        done = run_mavsysid("experiment", "--connect", f"{cable.ground}:115200", "--vehicle",
                            "quad_x", "--budget", "8", "--samples", "60", "--refine-steps",
                            "50", "--seed", "1", "--box", "-2,-2,0.5,2,2,2.5", "--speedup",
                            SPEEDUP, "--lockstep", "--report", str(tmp_path / "report"),
                            "--log-dir", str(logs), cwd=tmp_path, timeout=600.0)
    flight = flight_dir(logs)
    meta = json.loads((flight / "meta.json").read_text())
    assert meta["connection"] == f"{cable.ground}:115200"
    assert meta["status"] == "complete", done.stderr[-3000:]
    assert (flight / "trajectory.json").is_file() and (flight / "flight.tlog").is_file()
    if done.returncode == 0:
        assert (flight / "estimate.json").is_file()
        assert (tmp_path / "report" / "index.html").is_file()
        assert done.stdout.strip().splitlines()[-1].startswith("next: mavsysid diagnose ")
    else:
        last = done.stderr.strip().splitlines()[-1]
        assert done.returncode == 3 and "but no estimate" in last, done.stderr[-3000:]
