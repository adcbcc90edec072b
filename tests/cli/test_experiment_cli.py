"""``mavsysid experiment``: bad options and an unanswered link are one line each, before
anything is planned or flown; against `mavsysid sim` (its own process, TCP on 127.0.0.1)
the limits are read, the plan flown and θ estimated, all kept in one flight directory."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mavsysid.flight.loopback_ports import free_tcp_port

from mavsysid.cli import main
from tests.support.stream_flights import SimProcess

BAD_OPTIONS = {
    "speedup 0": (["--speedup", "0"], "--speedup"),
    "negative prior sigma": (["--prior-sigma", "-1"], "--prior-sigma"),
    "box with 3 numbers": (["--box", "1,2,3"], "--box"),
    "heartbeat timeout nan": (["--heartbeat-timeout", "nan"], "--heartbeat-timeout"),
    "tracking limit 0": (["--max-tracking-error", "0"], "--max-tracking-error"),
    "imbalance 1": (["--max-motor-imbalance", "1"], "--max-motor-imbalance"),
    "report of a dry run": (["--dry-run", "--report", "r"], "--dry-run estimates nothing"),
}


@pytest.mark.parametrize("extra,named", BAD_OPTIONS.values(), ids=BAD_OPTIONS.keys())
def test_bad_options_exit_2_before_connecting(tmp_path: Path, capsys, extra, named):
    """A bad option is exit 2 in one line naming it; no link is opened, nothing written."""
    link = f"tcp:127.0.0.1:{free_tcp_port()}"
    code = main(["experiment", "--connect", link, "--vehicle", "quad_x",
                 "--log-dir", str(tmp_path / "logs"), *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and named in err and "\n" not in err, err
    assert not (tmp_path / "logs").exists()


def test_no_box_anywhere_exits_2_before_connecting(tmp_path: Path, capsys):
    """Without --box and without a [flight] box in the vehicle file nothing is planned or
    flown: exit 2 in one line naming both."""
    text = (Path(__file__).resolve().parents[2] / "vehicle" / "configs" / "quad_x.toml"
            ).read_text()
    start = text.index("[flight]")
    end = text.find("\n[", start + 1)
    vehicle = tmp_path / "boxless.toml"
    vehicle.write_text(text[:start] + (text[end + 1:] if end >= 0 else ""))
    link = f"tcp:127.0.0.1:{free_tcp_port()}"
    code = main(["experiment", "--connect", link, "--vehicle", str(vehicle),
                 "--log-dir", str(tmp_path / "logs")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "[flight] box" in err and "--box" in err and "\n" not in err, err
    assert not (tmp_path / "logs").exists()


def test_no_vehicle_on_the_link_exits_3_in_one_line(tmp_path: Path, capsys):
    """A link nobody answers on fails in one line naming it, before any planning."""
    link = f"tcp:127.0.0.1:{free_tcp_port()}"
    code = main(["-q", "experiment", "--connect", link, "--vehicle", "quad_x",
                 "--log-dir", str(tmp_path / "logs")])
    err = capsys.readouterr().err.strip()
    assert code == 3 and link in err and "\n" not in err, err
    assert not (tmp_path / "logs").exists()


@pytest.mark.slow
def test_experiment_against_the_sim_keeps_everything_in_one_directory(tmp_path: Path, capsys):
    """Limits read from the sim, a plan within them flown without raising any, and θ
    estimated from the flight's tlog: exit 0, or a refused estimate in one line naming the
    flight directory; either way the plan and the recorded flight are kept together."""
    port = free_tcp_port()
    logs = tmp_path / "logs"
    # Lock-stepped, so the flight is the same on a busy machine and takes less wall time.
    with SimProcess(tmp_path / "sim", "--connect", f"tcpin:127.0.0.1:{port}", "--vehicle",
                    "quad_x", "--speedup", "8") as sim:
        sim.wait_ready(timeout=90.0)
        code = main(["experiment", "--connect", f"tcp:127.0.0.1:{port}", "--vehicle",
                     "quad_x", "--budget", "10", "--samples", "80", "--refine-steps", "100",
                     "--seed", "1", "--speedup", "8", "--lockstep", "--log-dir", str(logs)])
    out, err = capsys.readouterr()
    (flight,) = [p for p in logs.iterdir() if p.is_dir()]
    for name in ("trajectory.json", "flight.tlog", "pose.csv", "meta.json"):
        assert (flight / name).is_file(), name
    meta = json.loads((flight / "meta.json").read_text())
    assert meta["autopilot_limits"]["set_limits"] is False
    assert "planning within the limits of the ArduPilot vehicle on tcp:127.0.0.1" in err
    if code == 0:
        assert (flight / "estimate.json").is_file()
        assert f"wrote estimate {flight / 'estimate.json'}" in out
    else:
        last = err.strip().splitlines()[-1]
        assert code == 3 and f"flown and recorded in {flight}, but no estimate" in last, err


@pytest.mark.slow
def test_dry_run_plans_and_checks_and_arms_nothing(tmp_path: Path, capsys):
    """``experiment --dry-run``: the limits read, a plan made and every check of the flight
    run on the vehicle (lock-stepped sim); nothing armed, no estimate; the last line says
    what comes next."""
    from tests.support.stream_flights import flight_dir, read_tlog

    port = free_tcp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"tcpin:127.0.0.1:{port}", "--vehicle",
                    "quad_x", "--speedup", "8") as sim:
        sim.wait_ready(timeout=90.0)
        code = main(["experiment", "--connect", f"tcp:127.0.0.1:{port}", "--vehicle",
                     "quad_x", "--budget", "8", "--samples", "40", "--refine-steps", "0",
                     "--seed", "1", "--speedup", "8", "--lockstep", "--dry-run",
                     "--log-dir", str(logs)])
    out, err = capsys.readouterr()
    assert code == 0, err[-3000:]
    flight = flight_dir(logs)
    assert "Dry run of the" in out and out.strip().splitlines()[-1] == (
        "next: the same command without --dry-run flies it")
    assert not (flight / "estimate.json").exists() and (flight / "trajectory.json").is_file()
    meta = json.loads((flight / "meta.json").read_text())
    assert meta["dry_run"] and meta["status"] == "complete"
    sent = [m for _, m in read_tlog(flight / "flight.tlog") if m.get_srcSystem() == 255]
    assert not [m for m in sent if m.get_type() == "COMMAND_LONG" and m.command == 400]
    assert not [m for m in sent if m.get_type() == "PARAM_SET"]
