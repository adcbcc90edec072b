"""The pose log ``pose.csv``: its format, the `PoseLog` it holds, and its reader.

A pose log (docs/architecture.md, "Pose log") is CSV text: a header row, then one row per sample
with ``t`` (s, strictly increasing), ``x, y, z`` (m, world ENU), ``qw, qx, qy, qz``
(Hamilton quaternion [w, x, y, z], body → world), ``n1 … nk`` (rad/s, actual rotor
speeds in the vehicle config's rotor order) and optionally more columns, which readers
keep as extras. Readers find columns by header name, so their order is free. The writer
is `mavsysid.formats.poselog_writer.PoseLogWriter`.
"""

from __future__ import annotations

import contextlib
import csv
import io
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from mavsysid.errors import LogFormatError

__all__ = [
    "POSE_COLUMNS", "QUATERNION_TOLERANCE", "ROTOR_COLUMN", "PoseLog", "TruncatedLogWarning",
    "check_positive_count", "parse_plain_rows", "read_pose_log", "read_text_file",
    "rotor_columns",
]

#: Required leading columns of a pose log, in the order the writer emits them.
POSE_COLUMNS: tuple[str, ...] = ("t", "x", "y", "z", "qw", "qx", "qy", "qz")

#: Beyond this a quaternion is not a rotation that lost digits but a wrong column or unit.
QUATERNION_TOLERANCE = 1e-3

#: Names of rotor-speed columns: n1, n2, … (no leading zero).
ROTOR_COLUMN = re.compile(r"n([1-9][0-9]*)")

# Text of decimal numbers, commas and line ends only. On such fields pandas' C parser
# accepts exactly what numpy's loadtxt and Python's float accept, with the same values
# (checked field by field in the tests); anything else (nan, inf, true, …) it may not.
_PLAIN_TEXT = re.compile(r"[0-9eE.+\- \t\n,]*")


class TruncatedLogWarning(UserWarning):
    """The last row of a pose log was incomplete (writer killed mid-row) and was dropped."""


def rotor_columns(k: int) -> tuple[str, ...]:
    """Names of the rotor-speed columns of a ``k``-rotor vehicle: ``("n1", …, "nk")``."""
    return tuple(f"n{i}" for i in range(1, k + 1))


def _frozen(a: Any, shape: tuple[int | None, ...], name: str, want: str) -> np.ndarray:
    """A read-only float copy of ``a``; ``None`` in ``shape`` matches any length."""
    arr = np.array(a, dtype=np.float64)  # a copy: freezing must not touch the caller's array
    if arr.ndim != len(shape) or any(
        s not in (None, m) for s, m in zip(shape, arr.shape, strict=True)
    ):
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def check_positive_count(value: Any, name: str, allow_none: bool = False) -> None:
    """Check that ``value`` is a positive int (a rotor count, a row count …).

    Parameters
    ----------
    value : Any
        The value to check; a bool is not an int here.
    name : str
        Its name in the message.
    allow_none : bool
        Accept None too (an optional count).

    Raises
    ------
    ValueError
        Not a positive int (a programming error of the caller, not a file problem).
    """
    ok = isinstance(value, int) and not isinstance(value, bool) and value >= 1
    if not (ok or (allow_none and value is None)):
        raise ValueError(f"{name} must be a positive int, got {value!r}")


@dataclass(frozen=True, eq=False)
class PoseLog:
    """A recorded flight: pose and rotor speeds at N sample times (arrays are read-only copies).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    position : ndarray, shape (N, 3)
        Body origin in the world frame, m, ENU.
    quaternion : ndarray, shape (N, 4)
        Unit Hamilton quaternion [w, x, y, z] rotating body → world.
    rotor_speeds : ndarray, shape (N, k)
        Actual rotor speeds, rad/s, in the vehicle config's rotor order.
    extra : dict of str to ndarray of shape (N,)
        Further columns of the file (setpoints, velocities, …), in file order.
    path : Path or None
        The file the log was read from.
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    path: Path | None = None

    def __post_init__(self) -> None:
        t = _frozen(self.t, (None,), "t", "(N,)")
        n = t.shape[0]
        if n > 1 and not (np.diff(t) > 0.0).all():  # slice_time relies on it
            raise ValueError("t must be strictly increasing")
        values = {
            "t": t,
            "position": _frozen(self.position, (n, 3), "position", f"(N, 3), N = {n}"),
            "quaternion": _frozen(self.quaternion, (n, 4), "quaternion", f"(N, 4), N = {n}"),
            "rotor_speeds": _frozen(self.rotor_speeds, (n, None), "rotor_speeds",
                                    f"(N, k), N = {n}"),
            "extra": {str(c): _frozen(v, (n,), f"extra[{c!r}]", f"(N,), N = {n}")
                      for c, v in self.extra.items()},
            "path": None if self.path is None else Path(self.path),
        }
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def rotor_count(self) -> int:
        """Number of rotors k."""
        return int(self.rotor_speeds.shape[1])

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, s (0.0 for fewer than two samples)."""
        return float(self.t[-1] - self.t[0]) if len(self) > 1 else 0.0

    def slice_time(self, t0: float, t1: float) -> PoseLog:
        """The samples with ``t0 <= t <= t1`` (s) as a new `PoseLog`, possibly empty."""
        if not t1 >= t0:
            raise ValueError(f"slice_time needs t0 <= t1, got t0={t0}, t1={t1}")
        i, j = np.searchsorted(self.t, t0, "left"), np.searchsorted(self.t, t1, "right")
        return PoseLog(self.t[i:j], self.position[i:j], self.quaternion[i:j],
                       self.rotor_speeds[i:j], {c: v[i:j] for c, v in self.extra.items()},
                       self.path)


def read_text_file(path: Path, encoding: str = "utf-8") -> str:
    """The text of a file; anything unreadable is a one-line `LogFormatError`."""
    try:
        return path.read_bytes().decode(encoding)
    except OSError as e:
        raise LogFormatError(f"{path}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise LogFormatError(f"{path}: not a text file (byte {e.start} is not UTF-8)") from None


def parse_plain_rows(text: str, columns: Sequence[int] | None = None) -> np.ndarray | None:
    """Parse CSV data rows of plain decimal numbers in bulk, with pandas' C parser.

    Parameters
    ----------
    text : str
        The data rows, no header, LF line ends; the caller has checked that every row
        has the same field count.
    columns : sequence of int, optional
        Indices of the columns to return, in this order; all if None.

    Returns
    -------
    ndarray of shape (N, m), or None
        None if the text holds anything but plain decimal numbers (nan, inf, words, a
        malformed number): the caller then parses it field by field, which can name
        the line and column of a bad field.
    """
    if not text or _PLAIN_TEXT.fullmatch(text) is None:
        return None
    try:
        frame = pd.read_csv(io.StringIO(text), header=None, usecols=columns, dtype=np.float64,
                            na_filter=False, quoting=csv.QUOTE_NONE, engine="c")
    except ValueError:  # pandas' ParserError and EmptyDataError are ValueErrors
        return None
    return frame.to_numpy() if columns is None else frame[list(columns)].to_numpy()


def _is_number(text: str) -> bool:
    """Whether a CSV field is a number, as numpy's loadtxt parses it."""
    try:
        float(text)
    except ValueError:
        return False
    return "_" not in text  # float() accepts digit separators, loadtxt does not


def _field(body: list[str], i: int, j: int) -> str:
    """Field j of data row i, fit for a one-line message."""
    text = body[i].split(",")[j].strip()
    return repr(text if len(text) <= 24 else text[:24] + "…")


def read_pose_log(path: str | Path, rotor_count: int | None = None) -> PoseLog:
    """Read and fully check a pose log.

    Parameters
    ----------
    path : str or Path
        The ``pose.csv`` file (UTF-8, LF or CRLF line ends).
    rotor_count : int, optional
        The vehicle config's rotor count k: the file must have exactly the rotor columns
        ``n1 … nk``. If None, all ``n<i>`` columns are taken; they must be ``n1 … nm``.

    Returns
    -------
    PoseLog
        Quaternions renormalised (norm errors up to 1e-3 are accepted).

    Raises
    ------
    LogFormatError
        One line naming the file, and the line number and column where they apply.

    Warns
    -----
    TruncatedLogWarning
        The last line lacks its newline and is incomplete (field count, or a field not
        a number), as a writer killed mid-row leaves it: it is dropped.
    """
    check_positive_count(rotor_count, "rotor_count", allow_none=True)
    path = Path(path)
    text = read_text_file(path, "utf-8-sig")
    text = text.replace("\r\n", "\n") if "\r" in text else text
    lines = text.split("\n")
    newline_at_end = lines[-1] == ""
    if newline_at_end:
        lines.pop()
    if not lines or not lines[0].strip():
        raise LogFormatError(f"{path}: " + ("line 1 is empty, expected the header row"
                                            if text.strip() else "empty file, no header row"))
    names = [c.strip() for c in next(csv.reader([lines[0]]))]
    cols = _locate_columns(path, names, rotor_count)
    body, ncol = lines[1:], len(names)
    _check_rows(path, body, ncol, newline_at_end)
    data = parse_plain_rows("\n".join(body))
    if data is None:
        data = _parse_body(path, body, names)
    q = _checked_quaternions(path, data, body, names, cols)
    known = set(cols.values())
    return PoseLog(
        t=data[:, cols["t"]],
        position=data[:, [cols[c] for c in POSE_COLUMNS[1:4]]],
        quaternion=q,
        rotor_speeds=data[:, [cols[c] for c in cols if c not in POSE_COLUMNS]],
        extra={names[j]: data[:, j] for j in range(ncol) if j not in known},
        path=path,
    )


def _check_rows(path: Path, body: list[str], ncol: int, newline_at_end: bool) -> None:
    """Drop a truncated last row (with a warning); refuse no rows or a wrong field count."""
    # A writer killed mid-row leaves a last line without newline that is short or cut
    # inside a number. Anything else wrong is an error at its line.
    if body and not newline_at_end:
        fields = body[-1].split(",")
        if len(fields) != ncol or not all(map(_is_number, fields)):
            body.pop()
            if not body:
                raise LogFormatError(f"{path}: no samples (the only data row is incomplete)")
            # stacklevel 3: the warning names read_pose_log's caller.
            warnings.warn(f"{path}: line {len(body) + 2} is incomplete (truncated write?) and "
                          f"was dropped; kept the {len(body)} complete rows",
                          TruncatedLogWarning, stacklevel=3)
    if not body:
        raise LogFormatError(f"{path}: no samples, only a header row")
    if any(line.count(",") != ncol - 1 for line in body):
        i = next(i for i, line in enumerate(body) if line.count(",") != ncol - 1)
        found = "is empty" if not body[i].strip() else f"has {body[i].count(',') + 1} fields"
        raise LogFormatError(f"{path}: line {i + 2} {found}, the header has {ncol}")


def _checked_quaternions(path: Path, data: np.ndarray, body: list[str], names: list[str],
                         cols: dict[str, int]) -> np.ndarray:
    """Check values finite, t increasing and quaternions unit; the renormalised (N, 4)."""
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise LogFormatError(f"{path}: line {i + 2}, column {names[j]!r}: "
                             f"{_field(body, i, j)} is not finite")
    t = data[:, cols["t"]]
    step = np.diff(t) <= 0.0
    if step.any():
        i = int(np.argmax(step)) + 1
        raise LogFormatError(f"{path}: line {i + 2}: t = {_field(body, i, cols['t'])} does not "
                             f"increase (previous t = {_field(body, i - 1, cols['t'])})")
    q = data[:, [cols[c] for c in POSE_COLUMNS[4:]]]
    norm = np.linalg.norm(q, axis=1)
    off = np.abs(norm - 1.0) > QUATERNION_TOLERANCE
    if off.any():
        i = int(np.argmax(off))
        raise LogFormatError(f"{path}: line {i + 2}: quaternion (qw, qx, qy, qz) has norm "
                             f"{norm[i]:.6g}, not 1 within {QUATERNION_TOLERANCE:g}")
    return q / norm[:, None]


def _locate_columns(path: Path, names: list[str], rotor_count: int | None) -> dict[str, int]:
    """Index in the header of each pose column, then of n1 … nk."""
    seen: set[str] = set()
    for j, c in enumerate(names):
        if not c or c in seen:
            what = "has no name" if not c else f"repeats the name {c!r}"
            raise LogFormatError(f"{path}: header column {j + 1} {what}")
        seen.add(c)
    missing = [c for c in POSE_COLUMNS if c not in seen]
    if missing:
        raise LogFormatError(f"{path}: missing required column(s) {', '.join(missing)}")
    found = sorted(int(m.group(1)) for c in names if (m := ROTOR_COLUMN.fullmatch(c)))
    shown = ", ".join(f"n{i}" for i in found) or "none"
    if rotor_count is not None and found != list(range(1, rotor_count + 1)):
        raise LogFormatError(f"{path}: expected {rotor_count} rotor speed columns "
                             f"n1..n{rotor_count} from the vehicle config, found {len(found)} "
                             f"({shown})")
    if not found:
        raise LogFormatError(f"{path}: no rotor speed columns n1..nk")
    if found != list(range(1, len(found) + 1)):
        raise LogFormatError(f"{path}: rotor speed columns must be n1..nk without gaps, "
                             f"found {shown}")
    return {c: names.index(c) for c in POSE_COLUMNS + rotor_columns(len(found))}


def _parse_body(path: Path, body: list[str], names: list[str]) -> np.ndarray:
    """Parse data rows that are not all plain numbers, or raise naming the bad field."""
    with warnings.catch_warnings(), contextlib.suppress(ValueError, UserWarning):
        warnings.simplefilter("error")
        data = np.loadtxt(body, delimiter=",", dtype=np.float64, comments=None, ndmin=2)
        if data.shape == (len(body), len(names)):
            return data
    # The fast parser's message lacks the line and column name: find the field ourselves.
    for i, line in enumerate(body):
        for j, text in enumerate(line.split(",")):
            if not _is_number(text):
                raise LogFormatError(f"{path}: line {i + 2}, column {names[j]!r}: "
                                     f"{_field(body, i, j)} is not a number")
    raise LogFormatError(f"{path}: the samples could not be parsed as numbers")
