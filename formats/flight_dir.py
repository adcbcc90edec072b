"""The files of a flight directory ``logs/<flight>/`` besides the pose log.

``meta.json`` is written atomically (a reader sees the old file or the new one, never
half), and new flight directories are created atomically, so two recorders never share one.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.formats.poselog import read_text_file

from mavsysid.errors import InputError, LogFormatError

__all__ = ["STREAM_SOURCE", "new_flight_dir", "read_meta", "write_json_atomic", "write_meta"]

#: ``meta.json``'s ``"source"`` for a flight recorded by ``mavsysid stream``: its
#: ``pose.csv`` holds the vehicle's telemetry, the autopilot's own estimate of the pose.
STREAM_SOURCE = "mavlink-stream"


def write_meta(path: str | Path, meta: Mapping[str, Any]) -> None:
    """Write ``meta.json`` atomically (see `write_json_atomic`).

    Parameters
    ----------
    path : str or Path
        The ``meta.json`` file.
    meta : Mapping
        The metadata document.
    """
    write_json_atomic(path, meta)


def write_json_atomic(path: str | Path, data: Mapping[str, Any]) -> None:
    """Write JSON atomically: a reader sees the old file or the new one, never half.

    numpy scalars and arrays are stored as numbers and lists, paths as strings. Values
    JSON cannot hold (NaN and infinity included) raise before the disk is touched.

    Parameters
    ----------
    path : str or Path
        The file to (re)write.
    data : Mapping
        The JSON document.
    """
    path = Path(path)
    text = json.dumps(dict(data), indent=2, ensure_ascii=False, allow_nan=False,
                      default=_json_default) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"meta value {value!r} of type {type(value).__name__} is not JSON")


def read_meta(path: str | Path) -> dict[str, Any]:
    """Read ``meta.json``; a missing or malformed file is a one-line `LogFormatError`.

    Parameters
    ----------
    path : str or Path
        The ``meta.json`` file.
    """
    path = Path(path)
    try:
        meta = json.loads(read_text_file(path, "utf-8"))
    except json.JSONDecodeError as e:
        raise LogFormatError(f"{path}: line {e.lineno}, column {e.colno}: invalid JSON: "
                             f"{e.msg}") from None
    if not isinstance(meta, dict):
        raise LogFormatError(f"{path}: metadata must be a JSON object, "
                             f"found {type(meta).__name__}")
    return meta


def _timestamp() -> str:
    return time.strftime("%Y%m%d-%H%M%S")


def new_flight_dir(root: str | Path = "logs", name: str | None = None) -> Path:
    """Create and return a new, empty flight directory ``root/<name>``.

    ``name`` defaults to the local time ``%Y%m%d-%H%M%S``, suffixed ``-2``, ``-3``, … if
    taken; an explicit ``name`` that exists is an `InputError`. ``root`` is created if
    missing. Creation is atomic, so concurrent callers never share a directory.

    Parameters
    ----------
    root : str or Path
        Folder the flight directory is made in.
    name : str, optional
        Name of the directory; None: the local time.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    if name is not None:
        if name in ("", ".", "..") or Path(name).name != name or "\\" in name:
            raise InputError(f"flight name {name!r} must be a plain directory name")
        try:
            (root / name).mkdir()
        except FileExistsError:
            raise InputError(f"flight directory {root / name} already exists") from None
        return root / name
    stamp = _timestamp()
    for i in range(1, 10_000):
        with contextlib.suppress(FileExistsError):
            (path := root / (stamp if i == 1 else f"{stamp}-{i}")).mkdir()
            return path
    raise InputError(f"too many flight directories named {stamp}-* in {root}")
