"""Autopilot parameter dumps: ``NAME VALUE`` lines, as ArduPilot and PX4 tools save them.

Accepted, one parameter a line (blank lines and ``#`` comments skipped, later lines
winning, as ArduPilot's ``--defaults`` files do):

- ArduPilot ``.parm`` (SITL defaults, MAVProxy ``param save``): ``NAME VALUE``,
  separated by spaces or tabs;
- Mission Planner ``.param``: ``NAME,VALUE``;
- QGroundControl ``.params`` (ArduPilot or PX4): ``SYSTEM COMPONENT NAME VALUE TYPE``,
  tab-separated.

Values are the parameter's own units (cm/s, cdeg, …), as the autopilot stores them.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from mavsysid.formats.poselog import read_text_file

from mavsysid.errors import InputError

__all__ = ["parse_parameter_lines", "read_parameter_file"]

#: MAVLink parameter ids: at most 16 characters.
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,15}")


def _parameter(fields: list[str]) -> tuple[str, str] | None:
    """(name, value text) of one line's fields, or None when it fits no known layout."""
    if len(fields) == 2:
        return fields[0], fields[1]
    if len(fields) == 5 and fields[0].isdigit() and fields[1].isdigit():
        return fields[2], fields[3]
    return None


def parse_parameter_lines(text: str, source: str) -> dict[str, float]:
    """Parameter name → value of a parameter dump's ``text`` (see the module docstring).

    Parameters
    ----------
    text : str
        The file's contents.
    source : str
        The file name, for messages.

    Raises
    ------
    InputError
        A line in no accepted layout, a bad name or a non-finite value (one line naming
        ``source`` and the line number), or no parameter at all.
    """
    values: dict[str, float] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split(",") if "," in line else line.split()
        found = _parameter([f.strip() for f in fields])
        if found is None or not _NAME.fullmatch(found[0]):
            raise InputError(f"{source}:{number}: expected 'NAME VALUE' (or 'NAME,VALUE', or "
                             f"QGroundControl's 5 columns), got {raw.strip()[:60]!r}")
        try:
            value = float(found[1])
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise InputError(f"{source}:{number}: {found[0]}: expected a finite number, "
                             f"got {found[1][:30]!r}")
        values[found[0].upper()] = value
    if not values:
        raise InputError(f"{source}: no parameters (expected 'NAME VALUE' lines)")
    return values


def read_parameter_file(path: str | Path) -> dict[str, float]:
    """`parse_parameter_lines` of the file at ``path`` (missing or unreadable: InputError).

    Parameters
    ----------
    path : str or Path
        The parameter file (``.parm``, ``.param``, ``.params``).
    """
    return parse_parameter_lines(read_text_file(Path(path)), str(path))
