"""The calibration window: which part of a log the estimator uses.

A real log holds take-off, landing and time on the ground around the part flown for
identification. `choose_window` picks, in this order:

1. the window given (``--start``/``--end``, s on the log's clock);
2. the trajectory `mavsysid stream` flew: ``trajectory_window`` of the ``meta.json``
   beside the log (pose.csv and flight.tlog share its clock, the vehicle's time since boot);
3. the longest span in which the autopilot was in the mode an external controller flies
   it in (GUIDED for ArduPilot, OFFBOARD for PX4), from the log's mode changes (tlog
   HEARTBEAT, ArduPilot ``MODE``, PX4 ``vehicle_status.nav_state``);
4. else the whole log.

It says which and why in an ``info:`` note.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.parsed_log import ModeChanges

from mavsysid.errors import InputError

__all__ = [
    "CONTROLLED_MODES",
    "TimeWindow",
    "choose_window",
    "control_spans",
    "longest_span",
    "meta_window",
    "spans_of",
]

#: Autopilot modes in which an external controller (the streamer) flies the vehicle.
CONTROLLED_MODES = frozenset({"GUIDED", "GUIDED_NOGPS", "OFFBOARD"})


@dataclass(frozen=True)
class TimeWindow:
    """A window of a log's time, s on its clock; None: open on that side.

    Attributes
    ----------
    start, end : float or None
        s.
    reason : str
        Why this window, for the note.
    """

    start: float | None
    end: float | None
    reason: str

    @property
    def bounds(self) -> tuple[float, float]:
        """``(start, end)`` with open sides as ∓∞, s."""
        return (-math.inf if self.start is None else self.start,
                math.inf if self.end is None else self.end)

    def describe(self) -> str:
        """``t = a to b s`` with "start"/"end" for open sides."""
        a = "the start" if self.start is None else f"{self.start:.3f}"
        b = "the end" if self.end is None else f"{self.end:.3f} s"
        return f"t = {a} to {b}"


def spans_of(t: np.ndarray, active: np.ndarray, events: bool,
             end: float) -> list[tuple[float, float]]:
    """Contiguous spans of ``active`` samples at times ``t`` (increasing), s.

    ``events``: each sample is a mode change, so a span lasts until the next inactive
    sample (or ``end``); else the samples are periodic reports and a span runs from its
    first to its last active report (conservative by up to one report period).
    """
    spans = []
    i, n = 0, len(t)
    while i < n:
        if not active[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and active[j + 1]:
            j += 1
        stop = (t[j + 1] if j + 1 < n else end) if events else t[j]
        spans.append((float(t[i]), float(stop)))
        i = j + 1
    return spans


def longest_span(spans: list[tuple[float, float]] | tuple[tuple[float, float], ...]
                 ) -> tuple[float, float] | None:
    """The longest of ``spans`` (the first of equals), or None if there is none of length > 0."""
    best = max(spans, key=lambda s: s[1] - s[0], default=None)
    return None if best is None or best[1] <= best[0] else best


def meta_window(path: Path) -> tuple[float, float | None] | None:
    """``trajectory_window`` (start, end) of the ``meta.json`` beside ``path``, s, or None.

    ``end`` is None when the trajectory was cut off without an end being recorded.
    """
    meta_path = path.parent / "meta.json"
    if not meta_path.is_file():
        return None
    window = read_meta(meta_path).get("trajectory_window")
    if not isinstance(window, dict) or not isinstance(window.get("start"), (int, float)):
        return None
    end = window.get("end")
    return float(window["start"]), float(end) if isinstance(end, (int, float)) else None


def control_spans(modes: ModeChanges) -> tuple[tuple[float, float], ...]:
    """The spans of a log's modes in which an external controller flies (`CONTROLLED_MODES`).

    Parameters
    ----------
    modes : ModeChanges
        The log's modes, as its format's reader gives them.

    Returns
    -------
    tuple of (float, float)
        Start and end of each span, s (see `spans_of`).
    """
    active = np.array([mode in CONTROLLED_MODES for mode in modes.modes])
    return tuple(spans_of(modes.t, active, modes.events, modes.end))


def choose_window(path: Path, start: float | None, end: float | None,
                  control_spans: Callable[[], tuple[tuple[float, float], ...] | None]
                  ) -> TimeWindow | None:
    """The window to use (see the module docstring), or None for the whole log.

    Parameters
    ----------
    path : Path
        The flight log (its directory may hold ``meta.json``).
    start, end : float or None
        The window asked for, s; either given overrides the defaults.
    control_spans : callable
        Returns the log's GUIDED/OFFBOARD spans, s (None: the log has no mode
        information); called only when needed.
    """
    if start is not None or end is not None:
        if start is not None and end is not None and not start < end:
            raise InputError(f"{path}: window --start {start:g} s to --end {end:g} s: "
                             "expected start < end")
        return TimeWindow(start, end, "given by --start/--end")
    found = meta_window(path)
    if found is not None:
        return TimeWindow(found[0], found[1], "the trajectory flown by mavsysid stream "
                          "(meta.json trajectory_window)")
    span = longest_span(control_spans() or ())
    if span is not None:
        return TimeWindow(span[0], span[1], "the longest span in GUIDED/OFFBOARD mode in the "
                          "log, the part flown under external control")
    return None
