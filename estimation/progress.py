"""Stage messages while a long job works (``mavsysid estimate``'s progress on stderr).

The estimator announces its stages (filtering, noise fit, refinement, …) with
`report_stage`; nothing is shown unless a caller installs a listener with
`stage_listener`. A context variable carries the listener, so library callers, tests and
worker processes see nothing and the estimator keeps no global state. Long stages also
report their steps (`report_progress`: "batch refinement 2/30: cost …"), so a slow run
shows where it is.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import TextIO

__all__ = ["StageLog", "progress_wanted", "report_progress", "report_stage", "stage_listener"]

_LISTENER: ContextVar[Callable[[str], None] | None] = ContextVar(
    "mavsysid_stage_listener", default=None)


def report_stage(message: str) -> None:
    """Announce that a stage starts (``"filtering 6001 samples"``) to the active listener."""
    listener = _LISTENER.get()
    if listener is not None:
        listener(message)


def report_progress(stage: str, step: int, total: int, detail: str = "") -> None:
    """Announce step ``step`` of at most ``total`` of a long stage, with an optional detail.

    The listener receives ``"<stage> <step>/<total>: <detail>"``; nothing is formatted
    unless a listener is installed.
    """
    listener = _LISTENER.get()
    if listener is not None:
        listener(f"{stage} {step}/{total}" + (f": {detail}" if detail else ""))


@contextmanager
def stage_listener(listener: Callable[[str], None] | None) -> Iterator[None]:
    """Send every `report_stage` inside the ``with`` block to ``listener`` (None: nowhere)."""
    token = _LISTENER.set(listener)
    try:
        yield
    finally:
        _LISTENER.reset(token)


def progress_wanted(verbosity: int, stream: TextIO) -> bool:
    """Whether to show stage messages: asked for (``-v``), or by default on a terminal.

    Parameters
    ----------
    verbosity : int
        The CLI's verbosity: −1 with ``-q``, 0 by default, 1 and more with ``-v``.
    stream : file
        Where they would go (stderr). Piped or captured output gets them only with ``-v``,
        so scripts that read stderr see the one-line errors alone.
    """
    if verbosity < 0:
        return False
    isatty = getattr(stream, "isatty", None)
    return verbosity >= 1 or bool(isatty is not None and isatty())


class StageLog:
    """A listener that writes ``<prefix>: [  1.2 s] <stage>`` lines to a stream.

    Parameters
    ----------
    prefix : str
        E.g. ``"mavsysid estimate"``.
    stream : file
        Usually stderr; flushed after each line so the stage shows while it runs.
    clock : callable, optional
        Seconds (monotonic); the elapsed time is measured from construction.
    """

    def __init__(self, prefix: str, stream: TextIO,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.prefix = prefix
        self.stream = stream
        self.clock = clock
        self.start = clock()

    def __call__(self, message: str) -> None:
        """Write one stage line."""
        elapsed = self.clock() - self.start
        self.stream.write(f"{self.prefix}: [{elapsed:6.1f} s] {message}\n")
        self.stream.flush()
