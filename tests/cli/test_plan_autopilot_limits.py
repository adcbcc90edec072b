"""``mavsysid plan --autopilot-limits FILE``: the limits reach the planner; bad files exit 2."""

from __future__ import annotations

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import kinematic_limits

from mavsysid.cli import main
from tests.flight.ground.test_autopilot_limits import STOCK


def test_the_dumps_limits_reach_the_planner(tmp_path, planned):
    dump = tmp_path / "stock.parm"
    dump.write_text("".join(f"{k} {v:g}\n" for k, v in STOCK.items()) + "FRAME_TYPE 1\n")
    assert main(["-q", "plan", "--autopilot-limits", str(dump), "-o",
                 str(tmp_path / "t.json")]) == 0
    assert planned[-1].autopilot_limits == kinematic_limits(Autopilot.ARDUPILOT, STOCK)
    assert main(["-q", "plan", "-o", str(tmp_path / "u.json")]) == 0
    assert planned[-1].autopilot_limits is None


@pytest.mark.parametrize(("text", "problem"), [
    ("FRAME_TYPE 1\n", "holds none of the autopilot's position-controller limits"),
    ("ANGLE_MAX 3000\nMPC_TILTMAX_AIR 45\n", "holds both ArduPilot and PX4"),
    ("ANGLE_MAX thirty\n", ":1: ANGLE_MAX: expected a finite number"),
])
def test_a_dump_without_usable_limits_exits_2_in_one_line(tmp_path, capsys, planned, text,
                                                          problem):
    dump = tmp_path / "dump.parm"
    dump.write_text(text)
    assert main(["plan", "--autopilot-limits", str(dump), "-o", str(tmp_path / "t.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(dump) in err and problem in err, err
    assert not planned and not (tmp_path / "t.json").exists()


def test_the_autopilot_model_reaches_the_planner(tmp_path, capsys, planned):
    """``--autopilot-model``: the dump's loop parameters (others at their defaults) give
    the planner ArduCopter's loop; without it the setpoints count as flown exactly."""
    dump = tmp_path / "loop.parm"
    dump.write_text("".join(f"{k} {v:g}\n" for k, v in STOCK.items())
                    + "ATC_RAT_YAW_P 0.3\nMOT_THST_HOVER 0.39\n")
    assert main(["plan", "--autopilot-limits", str(dump), "--autopilot-model", "--no-preview",
                 "-o", str(tmp_path / "t.json")]) == 0
    loop = planned[-1].autopilot
    assert loop.autopilot == "ardupilot"
    assert loop.value("ATC_RAT_YAW_P") == 0.3 and loop.value("PSC_JERK_XY") == STOCK["PSC_JERK_XY"]
    assert loop.value("ATC_INPUT_TC") == 0.15  # not in the dump: the stock default
    assert "its loop from" in capsys.readouterr().err
    assert main(["-q", "plan", "--autopilot-limits", str(dump), "--no-preview",
                 "-o", str(tmp_path / "u.json")]) == 0
    assert planned[-1].autopilot is None
    assert main(["plan", "--autopilot-model", "-o", str(tmp_path / "v.json")]) == 2
    assert "--autopilot-model: only with --connect" in capsys.readouterr().err
