"""Every option default the guide states is the one ``--help`` has.

docs/guide.md writes defaults in its prose: "`--rotor-headroom F` keeps … (default 0.15)",
"`--prearm-timeout` (60 s)", "`--replan-time`, default 10 s". Each such statement is found
here and compared with the argparse default of the commands that have the option, so the
guide cannot drift from the code again (it once said 0 where ``plan --help`` said 0.15).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from mavsysid.cli.main import COMMAND_NAMES, build_parser

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide.md"
#: "`--name[ METAVAR]`" then, before any other backtick, "(default 5", ", default 5" or
#: "(5 unit" right after it; numbers may have thin spaces ("100 000").
_STATED = re.compile(r"`(--[a-z][a-z-]*)(?: [^`]*)?`(?P<between>[^`]{0,100}?)"
                     r"(?:\(default:? |, default:? |(?<=` )\()(?P<value>-?\d[\d ]*(?:\.\d+)?)"
                     r"(?=[\s:,;)%]|$)")


def _defaults() -> dict[str, dict[str, object]]:
    """Option → {command: its argparse default}, for every command's options."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out: dict[str, dict[str, object]] = {}
    for command in COMMAND_NAMES:
        for action in sub.choices[command]._actions:
            for name in action.option_strings:
                if name.startswith("--"):
                    out.setdefault(name, {})[command] = action.default
    return out


#: The commands each section of the guide (its "## " heading) is about.
SECTIONS = {"The demo": ("demo",), "The simulators": ("simulate", "sim"),
            "Planning a calibration flight": ("plan",),
            "Flying it safely": ("stream", "experiment", "restore"),
            "Estimating θ": ("estimate",), "Your own flight": ("estimate",),
            "Diagnosing what the model still gets wrong": ("diagnose",),
            "The paper's evaluation": ("evaluate",)}


def _stated() -> list[tuple[str, float, int, tuple[str, ...]]]:
    """(option, stated default, line, the section's commands) of each default stated."""
    text = GUIDE.read_text(encoding="utf-8")
    flat = text.replace("\n", " ")  # a statement may run over a line break
    headings = [(m.start(), m.group(1)) for m in re.finditer(r"^## (.+)$", text, re.M)]
    found = []
    for match in _STATED.finditer(flat):
        if "default" not in match.group(0) and match.group("between").strip():
            continue  # "(N unit)" only right after the option
        section = [name for start, name in headings if start < match.start()][-1:]
        commands = SECTIONS.get(section[0], ()) if section else ()
        found.append((match.group(1), float(match.group("value").replace(" ", "")),
                      text.count("\n", 0, match.start()) + 1, commands))
    return found


def test_the_guide_states_defaults_this_test_can_see():
    """The pattern finds the guide's statements (a reworded guide must keep them visible)."""
    options = {option for option, *_ in _stated()}
    assert {"--rotor-headroom", "--prearm-timeout", "--max-tracking-error",
            "--telemetry-rate", "--replan-time"} <= options, options


@pytest.mark.parametrize(("option", "value", "line", "commands"), _stated(),
                         ids=[f"{o}@{n}" for o, _, n, _ in _stated()])
def test_each_default_the_guide_states_is_the_code_s(option, value, line, commands):
    """The section's command(s) that have the option default to the stated value."""
    defaults = _defaults()
    assert option in defaults, f"docs/guide.md:{line}: {option} is no option of any command"
    mine = {c: d for c, d in defaults[option].items() if c in commands} or defaults[option]
    numeric = [float(d) for d in mine.values()
               if isinstance(d, int | float) and not isinstance(d, bool)]
    assert any(d == pytest.approx(value) for d in numeric), (
        f"docs/guide.md:{line}: {option} default {value:g}, but --help says "
        + ", ".join(f"{c} {d!r}" for c, d in mine.items()))
