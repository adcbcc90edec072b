"""Writing pose logs: `PoseLogWriter`, which puts every row on disk as it is recorded."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.formats.poselog import (
    POSE_COLUMNS,
    QUATERNION_TOLERANCE,
    ROTOR_COLUMN,
    PoseLog,
    check_positive_count,
    rotor_columns,
)

from mavsysid.errors import InputError

__all__ = ["PoseLogWriter", "write_pose_log"]

# Fixed point per column group, finer than any sensor: t 1e-6 s, position 1e-7 m,
# quaternion 1e-9, rotor speed 1e-4 rad/s. Extras have unknown units: 10 significant digits.
_FMT_T, _FMT_POS, _FMT_QUAT, _FMT_ROTOR, _FMT_EXTRA = "%.6f", "%.7f", "%.9f", "%.4f", "%.10g"
_CHUNK_ROWS = 20_000
_BAD_NAME_RE = re.compile(r"[\s,\"']")


class PoseLogWriter:
    """Writer of a pose log whose every row reaches the OS as soon as it is written.

    Parameters
    ----------
    path : str or Path
        The file to create, with any missing parent directories.
    rotor_count : int
        Number of rotors k (columns ``n1 … nk``).
    extra_columns : iterable of str
        Further columns, written after the rotor speeds.
    overwrite : bool, keyword-only
        Replace an existing file; otherwise that is an `InputError`, so that a new
        recording never destroys a flown one.

    Rows are flushed as written, to survive a crash of this process; `close` also
    ``fsync``s. Each row is checked first (shapes, finite values, unit quaternion, ``t``
    increasing by at least the written 1e-6 s; else ``ValueError``), so the file always
    reads back. Attributes: ``path``, ``columns`` (the header), ``rows_written``.
    """

    def __init__(self, path: str | Path, rotor_count: int, extra_columns: Iterable[str] = (),
                 *, overwrite: bool = False) -> None:
        check_positive_count(rotor_count, "rotor_count")
        extras = tuple(extra_columns)
        taken = set(POSE_COLUMNS)
        for c in extras:
            if not isinstance(c, str) or not c or _BAD_NAME_RE.search(c):
                raise ValueError(f"extra column name {c!r} must be non-empty text without "
                                 "whitespace, commas or quotes")
            if c in taken or ROTOR_COLUMN.fullmatch(c):
                raise ValueError(f"extra column name {c!r} is reserved or repeated")
            taken.add(c)
        self.path, self.rotor_count, self.extra_columns = Path(path), rotor_count, extras
        self.columns = POSE_COLUMNS + rotor_columns(rotor_count) + extras
        fmts = [_FMT_T, *[_FMT_POS] * 3, *[_FMT_QUAT] * 4, *[_FMT_ROTOR] * rotor_count]
        self._fmt = ",".join(fmts + [_FMT_EXTRA] * len(extras)) + "\n"
        self.rows_written = 0
        self._last_t = -math.inf  # as written, i.e. rounded to 1e-6 s
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._file = open(  # noqa: SIM115 - closed by close()
                self.path, "w" if overwrite else "x", encoding="utf-8", newline="\n")
        except FileExistsError:
            raise InputError(f"{self.path}: pose log already exists; "
                             "refusing to overwrite it") from None
        self._emit(",".join(self.columns) + "\n", 0, self._last_t)

    @property
    def closed(self) -> bool:
        """Whether `close` has been called."""
        return self._file.closed

    def write(self, t: float, position: Any, quaternion: Any, rotor_speeds: Any,
              extra: Mapping[str, float] | None = None) -> None:
        """Write one sample: t (s), position (3,) m, quaternion (4,) [w,x,y,z], speeds (k,) rad/s.

        ``extra`` maps every name of ``extra_columns`` to a float.
        """
        self._check_open()
        pos, quat, rot = (np.asarray(v, dtype=np.float64)
                          for v in (position, quaternion, rotor_speeds))
        ex = {} if extra is None else extra
        if (np.ndim(t) == 0 and pos.shape == (3,) and quat.shape == (4,)
                and rot.shape == (self.rotor_count,) and ex.keys() == set(self.extra_columns)
                and all(isinstance(v, float | int) or np.ndim(v) == 0 for v in ex.values())):
            # Fast path on plain floats: a recorder calls this at every sample.
            values = [float(t), *pos.tolist(), *quat.tolist(), *rot.tolist(),
                      *(float(ex[c]) for c in self.extra_columns)]
            t_out = round(values[0], 6)
            if (all(map(math.isfinite, values)) and t_out > self._last_t
                    and abs(math.hypot(*values[4:8]) - 1.0) <= QUATERNION_TOLERANCE):
                self._emit(self._fmt % tuple(values), 1, t_out)
                return
        if np.ndim(t) != 0:
            raise ValueError(f"t must be a scalar, got shape {np.shape(t)}")
        for name, arr, size in (("position", pos, 3), ("quaternion", quat, 4),
                                ("rotor_speeds", rot, self.rotor_count)):
            if arr.shape != (size,):
                raise ValueError(f"{name} must have shape ({size},), got {arr.shape}")
        # The block validator says what is wrong; should it find nothing, the row is written.
        self.write_rows(np.reshape(np.asarray(t, dtype=np.float64), (1,)), pos[None],
                        quat[None], rot[None], {c: np.ravel(v) for c, v in ex.items()})

    def write_rows(self, t: Any, position: Any, quaternion: Any, rotor_speeds: Any,
                   extra: Mapping[str, Any] | None = None) -> None:
        """Write N samples: t (N,) s, position (N, 3) m, quaternion (N, 4), speeds (N, k) rad/s.

        ``extra`` maps every name of ``extra_columns`` to an array of shape (N,).
        """
        self._check_open()
        t = np.asarray(t, dtype=np.float64)
        if t.ndim != 1:
            raise ValueError(f"t must have shape (N,), got {t.shape}")
        n, k = t.shape[0], self.rotor_count
        cols = [t[:, None]]
        for name, value, shape in (("position", position, (n, 3)),
                                   ("quaternion", quaternion, (n, 4)),
                                   ("rotor_speeds", rotor_speeds, (n, k))):
            cols.append(np.asarray(value, dtype=np.float64))
            if cols[-1].shape != shape:
                raise ValueError(f"{name} must have shape {shape} for {n} sample(s) of a "
                                 f"{k}-rotor log, got {cols[-1].shape}")
        extra = extra or {}
        if extra.keys() != set(self.extra_columns):
            raise ValueError(f"extra values must be exactly {list(self.extra_columns)}, "
                             f"got {sorted(extra)}")
        for c in self.extra_columns:
            cols.append(np.asarray(extra[c], dtype=np.float64).reshape(-1, 1))
            if cols[-1].shape != (n, 1):
                raise ValueError(f"extra[{c!r}] must have shape ({n},), got {np.shape(extra[c])}")
        block = np.hstack(cols)
        if n == 0:
            return
        bad = ~np.isfinite(block)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(f"{self.columns[j]} of sample {i} is {block[i, j]}; "
                             "a pose log holds finite values only")
        norm_err = np.abs(np.linalg.norm(cols[2], axis=1) - 1.0)
        if norm_err.max() > QUATERNION_TOLERANCE:
            i = int(np.argmax(norm_err))
            raise ValueError(f"quaternion of sample {i} has norm {1 + norm_err[i]:.6g}, not 1")
        # Compare t as written: samples closer than 1e-6 s would read back as repeated.
        step = np.diff(np.concatenate(([self._last_t], np.round(t, 6)))) <= 0.0
        if step.any():
            i = int(np.argmax(step))
            before = self._last_t if i == 0 else float(t[i - 1])
            raise ValueError(f"t must increase by at least 1e-6 s: sample {i} has "
                             f"t = {float(t[i])!r} after {before!r}")
        # One %-format per chunk runs in C with no Python loop per row; chunks bound memory.
        for i in range(0, n, _CHUNK_ROWS):
            part = block[i:i + _CHUNK_ROWS]
            self._file.write((self._fmt * len(part)) % tuple(part.ravel().tolist()))
        self._emit("", n, float(np.round(t[-1], 6)))

    def _check_open(self) -> None:
        if self._file.closed:
            raise ValueError(f"{self.path}: pose log writer is closed")

    def _emit(self, text: str, rows: int, last_t: float) -> None:
        self._file.write(text)
        self._file.flush()
        self.rows_written += rows
        self._last_t = last_t

    def close(self) -> None:
        """Flush, ``fsync`` and close the file. Closing twice is harmless."""
        if not self._file.closed:
            try:
                self._file.flush()
                os.fsync(self._file.fileno())
            finally:
                self._file.close()

    def __enter__(self) -> PoseLogWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def write_pose_log(path: str | Path, log: PoseLog, *, overwrite: bool = False) -> Path:
    """Write a whole `PoseLog` to ``path`` with a `PoseLogWriter`; return the path."""
    with PoseLogWriter(path, log.rotor_count, log.extra, overwrite=overwrite) as w:
        w.write_rows(log.t, log.position, log.quaternion, log.rotor_speeds, log.extra)
    return w.path
