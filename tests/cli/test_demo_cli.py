"""Tests of ``mavsysid demo``'s command line: bad input refused before anything flies."""

from __future__ import annotations

import pytest

from mavsysid.cli import main


@pytest.mark.parametrize(("argv", "fragment"), [
    (["--iterations", "0"], "--iterations 0"),
    (["--hidden-effect", "warp:x=1"], "unknown effect 'warp'"),
])
def test_demo_bad_input_exits_2(argv, fragment, tmp_path, capsys):
    """A bad option is one line and exit 2, before anything flies."""
    assert main(["demo", "--logs", str(tmp_path), *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err
    assert not any(tmp_path.iterdir())
