"""Field access shared by the DataFlash pose and motor readers, across log generations.

ArduPilot renamed fields over the years; what every generation shares is handled here:

- Time: ``TimeUS`` (µs since boot, ArduCopter 3.3 and later) or ``TimeMS`` (ms since boot,
  ArduCopter 3.2 and earlier, e.g. ``RCOU "Ihhhhhhhh" TimeMS,Chan1..Chan8``).
- Scaled integers: pymavlink's DFReader already applies the format characters' scale
  (``c``/``C``/``e``/``E`` × 0.01, ``L`` × 1e-7), so centi-degree ``ATT`` (``"QccccCCCC"``)
  and float-degree ``ATT`` (``"QffffffB"``) both read in degrees.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["Messages", "field_array", "field_format", "has_fields", "message_times"]

#: Parsed DataFlash messages by type name, in log order.
Messages = dict[str, list[Any]]


def has_fields(rows: list[Any], names: list[str]) -> bool:
    """Whether the messages (all of one type) have every named field."""
    return bool(rows) and all(n in rows[0].get_fieldnames() for n in names)


def field_array(rows: list[Any], names: list[str]) -> np.ndarray:
    """The named fields of the messages as floats, shape (len(rows), len(names))."""
    return np.array([[getattr(m, n) for n in names] for m in rows], dtype=float).reshape(
        len(rows), len(names))


def field_format(rows: list[Any], name: str) -> str:
    """The DataFlash format character of a field (``"f"``, ``"c"``, ``"e"``…)."""
    fmt = rows[0].fmt
    return fmt.format[fmt.colhash[name]]


def message_times(rows: list[Any]) -> np.ndarray:
    """Message times, s since boot, from ``TimeUS`` or (older logs) ``TimeMS``.

    Raises
    ------
    KeyError
        Neither field (the caller's parsing guard turns it into a one-line error).
    """
    if has_fields(rows, ["TimeUS"]):
        return field_array(rows, ["TimeUS"])[:, 0] * 1e-6
    if has_fields(rows, ["TimeMS"]):
        return field_array(rows, ["TimeMS"])[:, 0] * 1e-3
    raise KeyError(f"no TimeUS or TimeMS field in {rows[0].get_type()}")
