"""Autopilot parameter dumps (``plan --autopilot-limits``): the accepted layouts, one-line
refusals."""

from __future__ import annotations

import pytest
from mavsysid.formats.parameter_file import parse_parameter_lines, read_parameter_file

from mavsysid.errors import InputError


def test_the_three_layouts_comments_and_last_line_winning(tmp_path):
    text = ("# MAVProxy param save\nWPNAV_ACCEL 250\nPSC_JERK_XY\t5.5  # stock\n\n"
            "ANGLE_MAX,3000\n1\t1\tMPC_XY_VEL_MAX\t12\t9\nWPNAV_ACCEL 800\n")
    path = tmp_path / "dump.parm"
    path.write_text(text)
    assert read_parameter_file(path) == {"WPNAV_ACCEL": 800.0, "PSC_JERK_XY": 5.5,
                                         "ANGLE_MAX": 3000.0, "MPC_XY_VEL_MAX": 12.0}


@pytest.mark.parametrize(("text", "where"), [
    ("WPNAV_ACCEL 250\nWPNAV_SPEED\n", "x.parm:2: expected 'NAME VALUE'"),
    ("ANGLE_MAX 30 deg\n", "x.parm:1: expected 'NAME VALUE'"),
    ("9ANGLE 30\n", "x.parm:1: expected 'NAME VALUE'"),
    ("ANGLE_MAX nan\n", "x.parm:1: ANGLE_MAX: expected a finite number"),
    ("PSC_JERK_XY 1e999\n", "x.parm:1: PSC_JERK_XY: expected a finite number"),
    ("# nothing\n\n", "x.parm: no parameters"),
])
def test_bad_lines_are_refused_in_one_line_naming_file_and_line(text, where):
    with pytest.raises(InputError) as refused:
        parse_parameter_lines(text, "x.parm")
    assert str(refused.value).startswith(where) and "\n" not in str(refused.value)


def test_a_missing_file_is_one_line(tmp_path):
    with pytest.raises(InputError, match=r"absent\.parm: cannot read"):
        read_parameter_file(tmp_path / "absent.parm")
