"""A streamed flight's directory, and writing its live ``meta.json`` off the setpoint path.

`stream_flight_dir` creates ``<log_dir>/<UTC time>_<name>/`` (``-2``, ``-3``, … when taken).

``meta.json`` is rewritten atomically (`mavsysid.formats.flight_dir.write_meta`: a
temporary file, ``fsync``, rename). An ``fsync`` can take a second on a busy disk, and the
setpoint stream must not wait for it: `MetaWriter` hands each snapshot to a thread of its
own, which writes only the newest one (a snapshot superseded before it was written is
dropped). The thread spends its time in system calls, which release the interpreter lock.
`MetaWriter.close` writes the last snapshot on the caller's thread, after the thread.
"""

from __future__ import annotations

import copy
import datetime as dt
import re
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from mavsysid.formats.flight_dir import new_flight_dir, write_meta

from mavsysid.errors import InputError

__all__ = ["MetaWriter", "stream_flight_dir"]


def stream_flight_dir(root: Path, stem: str) -> Path:
    """Create ``root/<UTC time>_<stem>`` (a suffix when taken); returns it."""
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    name = f"{stamp}_{re.sub(r'[^A-Za-z0-9._-]+', '-', stem) or 'flight'}"
    for i in range(1, 1000):
        try:
            return new_flight_dir(root, name if i == 1 else f"{name}-{i}")
        except InputError:
            if not (root / (name if i == 1 else f"{name}-{i}")).exists():
                raise
    raise InputError(f"too many flight directories named {name}-* in {root}")


class MetaWriter:
    """Writes snapshots of a metadata dict to ``path`` from a background thread.

    Parameters
    ----------
    path : Path
        The ``meta.json`` to (re)write.

    Attributes
    ----------
    writes : int
        Snapshots written so far.
    error : Exception or None
        The last write error of the thread (it keeps going: the final write reports).
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.writes = 0
        self.error: Exception | None = None
        self._pending: dict[str, Any] | None = None
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="meta-writer", daemon=True)
        self._thread.start()

    def submit(self, meta: Mapping[str, Any]) -> None:
        """Queue a snapshot of ``meta`` (copied now) to be written soon."""
        snapshot = copy.deepcopy(dict(meta))
        with self._cond:
            self._pending = snapshot
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._pending is None:
                    return
                meta, self._pending = self._pending, None
            try:
                write_meta(self.path, meta)
                self.writes += 1
            except (OSError, TypeError, ValueError) as error:
                self.error = error

    def close(self, final: Mapping[str, Any] | None = None) -> None:
        """Stop the thread (after its current write); then write ``final`` here, if given.

        Harmless twice. Errors of the final write propagate.
        """
        with self._cond:
            self._closed = True
            self._pending = None
            self._cond.notify()
        self._thread.join(timeout=30.0)
        if final is not None:
            write_meta(self.path, final)
            self.writes += 1
