"""Tests of ``mavsysid stream``'s bad-input handling (no vehicle needed)."""

from __future__ import annotations

import pytest

from mavsysid.cli import main
from tests.support.stream_flights import export_excitation


@pytest.fixture
def figure(tmp_path):
    """A 12 s excitation figure without a box."""
    return export_excitation(tmp_path / "figure.json", 12.0, box=None)


@pytest.mark.parametrize(("options", "expected"), [
    (["--box", "-2,-2,0.5,2,2,2.5", "--connect", "udp:14550"], "--connect udp:14550: expected"),
    ([], "has no flight box; give one with --box"),
    (["--box", "-2,-2,0.5,2,2"], "--box '-2,-2,0.5,2,2': expected 6"),
    (["--box", "-2,-2,0.5,2,2,2.5", "--rate", "0"], "--rate 0: expected a positive number"),
    (["--box", "-2,-2,0.5,2,2,2.5", "--vehicle", "nope"], "vehicle: a shipped vehicle name"),
])
def test_bad_input_exits_2_in_one_line_writing_nothing(tmp_path, figure, capsys, options,
                                                       expected):
    """Bad options or files: exit 2, one stderr line, no flight directory."""
    code = main(["stream", str(figure), "--log-dir", str(tmp_path / "logs"), *options])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and expected in err
    assert not (tmp_path / "logs").exists()


def test_missing_trajectory_file(tmp_path, capsys):
    """A trajectory file that does not exist is bad input."""
    assert main(["stream", str(tmp_path / "missing.json")]) == 2
    assert "missing.json" in capsys.readouterr().err
