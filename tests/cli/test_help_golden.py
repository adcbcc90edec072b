"""Every ``--help`` text against its golden copy (tests/cli/golden/help/), so that a change
to an option's name, default or wording is seen in review. Regenerate after a deliberate
change with ``MAVSYSID_UPDATE_GOLDEN=1 pytest tests/cli/test_help_golden.py``."""

from __future__ import annotations

import os
import re

import pytest

from mavsysid.cli.main import COMMAND_NAMES, help_text
from mavsysid.cli.options import OUTPUT_OPTION

GOLDEN = os.path.join(os.path.dirname(__file__), "golden", "help")
COMMANDS = [None, *COMMAND_NAMES]


def _help(command: str | None, monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", "100")  # argparse wraps to the terminal's width
    return help_text(command)


@pytest.mark.parametrize("command", COMMANDS, ids=[c or "mavsysid" for c in COMMANDS])
def test_help_matches_golden(command, monkeypatch):
    """The --help text is the reviewed one."""
    text = _help(command, monkeypatch)
    path = os.path.join(GOLDEN, f"{command or 'mavsysid'}.txt")
    if os.environ.get("MAVSYSID_UPDATE_GOLDEN") == "1":
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    with open(path, encoding="utf-8") as f:
        assert text == f.read()


@pytest.mark.parametrize("command", COMMANDS[1:])
def test_help_vocabulary(command, monkeypatch):
    """Every command: --version; no literal '%%'; one output-folder name; a listed effect
    vocabulary instead of a pointer to another command."""
    text = _help(command, monkeypatch)
    assert "--version" in text and "%%" not in text
    assert not re.search(r"--logs\b|--out\b", text)
    if "DIR" in text and command in ("demo", "simulate", "stream", "evaluate"):
        assert OUTPUT_OPTION in text
    assert "names as in" not in text
