"""``mavsysid plan --autopilot-limits LINK``: the limits read from a live vehicle (`mavsysid
sim` in its own process, TCP on 127.0.0.1) are the ones its parameters set; no vehicle, or
a signing key without a link, is one line."""

from __future__ import annotations

from pathlib import Path

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import kinematic_limits, parameter_names
from mavsysid.flight.loopback_ports import free_tcp_port
from mavsysid.flight.simvehicle.params import default_parameters
from mavsysid.vehicle.config import load_vehicle

from mavsysid.cli import main
from tests.support.stream_flights import SimProcess

VEHICLE = "quad_x"



def _sim_limits(autopilot: Autopilot):
    """The envelope the simulated vehicle's own parameter table sets."""
    table = default_parameters(autopilot, load_vehicle(VEHICLE))
    names = set(parameter_names(autopilot))
    return kinematic_limits(autopilot, {p.name: p.value for p in table if p.name in names})


@pytest.mark.slow
@pytest.mark.parametrize("autopilot", [Autopilot.ARDUPILOT, Autopilot.PX4])
def test_limits_are_read_from_the_live_vehicle(tmp_path: Path, planned, capsys, autopilot):
    """The planner gets exactly the envelope of the sim's parameters (PX4 integers come
    bytewise), read over TCP from `mavsysid sim`, with the source named on stderr."""
    port = free_tcp_port()
    expected = _sim_limits(autopilot)
    assert not expected.is_empty()
    with SimProcess(tmp_path / "sim", "--connect", f"tcpin:127.0.0.1:{port}", "--vehicle",
                    VEHICLE, "--autopilot", autopilot.name.lower(), lockstep=False) as sim:
        sim.wait_ready(timeout=90.0)
        link = f"tcp:127.0.0.1:{port}"
        code = main(["plan", "--vehicle", VEHICLE, "--autopilot-limits", link, "-o",
                     str(tmp_path / "t.json")])
        assert code == 0, capsys.readouterr().err
    assert planned[-1].autopilot_limits == expected
    err = capsys.readouterr().err
    name = "PX4" if autopilot is Autopilot.PX4 else "ArduPilot"
    assert f"limits read from the {name} vehicle on {link}" in err, err


def test_no_vehicle_on_the_link_exits_3_in_one_line(tmp_path: Path, planned, capsys):
    """A link nobody answers on fails in one line naming it, before any planning."""
    link = f"tcp:127.0.0.1:{free_tcp_port()}"
    assert main(["plan", "--autopilot-limits", link, "-o", str(tmp_path / "t.json")]) == 3
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and link in err, err
    assert not planned and not (tmp_path / "t.json").exists()


def test_a_file_named_like_a_link_is_read_as_a_file(tmp_path: Path, planned, monkeypatch):
    """An existing file is a parameter dump whatever its name."""
    from tests.flight.ground.test_autopilot_limits import STOCK

    monkeypatch.chdir(tmp_path)
    Path("tcp:127.0.0.1:5760").write_text("".join(f"{k} {v:g}\n" for k, v in STOCK.items()))
    assert main(["-q", "plan", "--autopilot-limits", "tcp:127.0.0.1:5760", "-o", "t.json"]) == 0
    assert planned[-1].autopilot_limits == kinematic_limits(Autopilot.ARDUPILOT, STOCK)


@pytest.mark.parametrize("limits", [None, "dump"])
def test_a_signing_key_without_a_link_exits_2(tmp_path: Path, planned, capsys, limits):
    """--signing-key is for a live vehicle only: alone or with a dump it is refused."""
    from tests.flight.ground.test_autopilot_limits import STOCK

    key = tmp_path / "key"
    key.write_text("secret\n")
    args = ["plan", "--signing-key", str(key), "-o", str(tmp_path / "t.json")]
    if limits is not None:
        dump = tmp_path / "stock.parm"
        dump.write_text("".join(f"{k} {v:g}\n" for k, v in STOCK.items()))
        args += ["--autopilot-limits", str(dump)]
    assert main(args) == 2
    assert "--signing-key: only with --connect LINK" in capsys.readouterr().err
    assert not planned


def test_connect_and_autopilot_limits_together_exit_2(tmp_path: Path, planned, capsys):
    """``--connect`` and its alias ``--autopilot-limits`` name the same thing: one of them."""
    link = f"tcp:127.0.0.1:{free_tcp_port()}"
    code = main(["plan", "--connect", link, "--autopilot-limits", link, "-o",
                 str(tmp_path / "t.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "give one" in err and "\n" not in err, err
    assert not planned


def test_connect_takes_a_link_not_a_file(tmp_path: Path, planned, capsys):
    """A parameter dump goes to ``--autopilot-limits FILE``; ``--connect`` wants a link."""
    dump = tmp_path / "stock.parm"
    dump.write_text("WPNAV_SPEED 500\n")
    code = main(["plan", "--connect", str(dump), "-o", str(tmp_path / "t.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--connect" in err and "\n" not in err, err
    assert not planned


def test_no_vehicle_on_connect_exits_3_in_one_line(tmp_path: Path, planned, capsys):
    """``plan --connect LINK`` with nobody on the link: one line naming it, nothing planned."""
    link = f"tcp:127.0.0.1:{free_tcp_port()}"
    assert main(["plan", "--connect", link, "-o", str(tmp_path / "t.json")]) == 3
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and link in err, err
    assert not planned and not (tmp_path / "t.json").exists()
