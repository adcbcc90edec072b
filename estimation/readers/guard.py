"""Calling third-party log parsers without their noise: prints captured, errors one line.

pymavlink and pyulog print progress and complaints to stdout/stderr and raise whatever
their parsing hits (struct.error, IndexError, …). The CLI contract is one line naming
the file, so every call into them goes through `parsing`.
"""

from __future__ import annotations

import contextlib
import importlib
import io
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

from mavsysid.errors import InputError, LogFormatError, MavsysidError

__all__ = ["import_parser", "one_line", "parsing"]


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
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            yield
    except MavsysidError:
        raise
    except Exception as exc:  # anything a parser raises on a malformed file
        raise LogFormatError(f"{path}: cannot be read as {kind} ({one_line(exc)})") from None


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
