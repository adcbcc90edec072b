"""Calling third-party log parsers, bounded: in file size and time, silent, errors one line.

pymavlink and pyulog print progress and complaints to stdout/stderr (pymavlink's compiled
DataFlash indexer straight to file descriptor 2) and raise whatever their parsing hits
(struct.error, IndexError, …). The CLI contract is one line naming the file, so every
call into them (`mavsysid.formats.tlog`, `mavsysid.formats.ulog`,
`mavsysid.formats.dataflash`) goes through `parsing`, which also bounds them: a file
larger than `MAX_LOG_BYTES` is refused before parsing (`check_log_size`), and a parse
running longer than `parse_budget` is stopped (pymavlink resyncs byte by byte through
corrupt data, and a few MB of junk already take seconds).
"""

from __future__ import annotations

import contextlib
import importlib
import io
import os
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

from mavsysid.errors import InputError, LogFormatError, MavsysidError

__all__ = ["MAX_LOG_BYTES", "PARSE_SECONDS", "PARSE_SECONDS_PER_MB", "check_log_size",
           "import_parser", "one_line", "parse_budget", "parsing"]

#: Largest flight log read, bytes (2 GiB: hours of 100 Hz pose.csv or of a full-rate
#: DataFlash log). The parsers hold a whole log in memory, several times its size.
MAX_LOG_BYTES = 2 * 1024**3
#: Time a parser may take on any file, s, plus `PARSE_SECONDS_PER_MB` per MB of it: far
#: above what a well-formed log takes (< 1 s/MB), a bound against a parser stuck in junk.
PARSE_SECONDS = 60.0
#: See `PARSE_SECONDS`, s per MB (10⁶ bytes).
PARSE_SECONDS_PER_MB = 5.0


class _ParseTimeout(BaseException):
    """Raised by the alarm inside a parser; a BaseException so its own handlers pass it."""


def check_log_size(path: Path) -> None:
    """Refuse, in one line, a file larger than `MAX_LOG_BYTES`."""
    size = path.stat().st_size
    if size > MAX_LOG_BYTES:
        raise LogFormatError(f"{path}: {size / 1e9:.3g} GB, larger than the "
                             f"{MAX_LOG_BYTES / 1e9:.3g} GB a flight log may have; cut the "
                             "calibration flight out of it")


def parse_budget(path: Path) -> float:
    """Seconds a parser may take on `path` (`PARSE_SECONDS` + `PARSE_SECONDS_PER_MB`/MB)."""
    return PARSE_SECONDS + PARSE_SECONDS_PER_MB * path.stat().st_size / 1e6


@contextlib.contextmanager
def _deadline(seconds: float, expired: list[bool]) -> Iterator[None]:
    """Raise `_ParseTimeout` after `seconds` and set ``expired[0]`` (main thread, no timer set).

    Raised inside a compiled extension, the exception may come out as another one (a
    ``SystemError``): ``expired`` tells the caller what happened.
    """
    usable = (hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
              and signal.getitimer(signal.ITIMER_REAL)[0] == 0.0)
    if not usable:
        yield
        return

    def expire(signum: int, frame: object) -> None:
        expired[0] = True
        raise _ParseTimeout

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


@contextlib.contextmanager
def _silent_descriptors() -> Iterator[None]:
    """File descriptors 1 and 2 to the null device, for output written below Python."""
    try:
        for stream in (sys.__stdout__, sys.__stderr__):
            if stream is not None:
                stream.flush()
        saved = [os.dup(1), os.dup(2)]
    except (OSError, ValueError):  # no such descriptors (a daemon): nothing to silence
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def one_line(exc: BaseException) -> str:
    """An exception as ``Type: message`` on one line."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@contextlib.contextmanager
def parsing(path: Path, kind: str) -> Iterator[None]:
    """Run a parser on `path` quietly; its exceptions become a one-line `LogFormatError`.

    Parameters
    ----------
    path : Path
        The file being parsed, named in the message.
    kind : str
        What the file should be ("a MAVLink telemetry log", …), named in the message.
    """
    sink = io.StringIO()
    check_log_size(path)
    budget, expired = parse_budget(path), [False]
    try:
        with (contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink),
              _silent_descriptors(), _deadline(budget, expired)):
            yield
    except MavsysidError:
        raise
    except (_ParseTimeout, Exception) as exc:  # anything a parser raises on a malformed file
        why = (f": parsing took longer than {budget:.0f} s (corrupt data?); gave up"
               if expired[0] else f" ({one_line(exc)})")
        raise LogFormatError(f"{path}: cannot be read as {kind}{why}") from None


def import_parser(module: str, path: Path) -> ModuleType:
    """Import a parser module (e.g. ``pymavlink.mavutil``); if missing, a one-line `InputError`.

    The log libraries are needed only for their formats, so they are imported on use.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        package = module.split(".")[0]
        raise InputError(f"{path}: reading {path.suffix} files needs the Python package "
                         f"{package} (pip install {package})") from None
