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
    ([], "no flight box from the operator; give --box"),
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


def _shifted(tmp_path, figure, metres: float, half_width: float):
    """The figure moved ``metres`` along x with a ±``half_width`` m box of its own."""
    import json

    doc = json.loads(figure.read_text())
    for segment in doc["segments"]:
        segment["position"][0][0] += metres
    doc["start"][0] += metres
    w = half_width
    doc["box"] = [-w, -w, -w, w, w, w]
    path = tmp_path / "shifted.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("options", [[], ["--vehicle", "firefly"],
                                     ["--box", "-2,-2,0.5,2,2,2.5"]])
def test_a_file_box_of_40_m_shifted_20_m_is_refused_before_connecting(tmp_path, figure,
                                                                       capsys, options):
    """The file's own ±40 m box with the flight 20 m away: one line, nothing connects, no
    flight directory; with the operator's box, the refusal names it."""
    path = _shifted(tmp_path, figure, 20.0, 40.0)
    code = main(["stream", str(path), "--log-dir", str(tmp_path / "logs"), *options])
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    if options:
        assert code == 3 and "flight refused: the trajectory leaves the box" in err
        assert "[-2,-2,0.5,2,2,2.5]" in err  # the operator's box, not the file's ±40 m
    else:
        assert code == 2 and "no flight box from the operator" in err
    assert not (tmp_path / "logs").exists()
