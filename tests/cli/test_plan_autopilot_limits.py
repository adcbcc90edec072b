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
