"""The pose log ``pose.csv``: its format, the `PoseLog` it holds, its reader and writer.

A pose log (docs/architecture.md, "Pose log") is CSV text: a header row, then one row per sample
with ``t`` (s, strictly increasing), ``x, y, z`` (m, world ENU), ``qw, qx, qy, qz``
(Hamilton quaternion [w, x, y, z], body → world), ``n1 … nk`` (rad/s, actual rotor
speeds in the vehicle config's rotor order), optionally the IMU on the same rows
(``gyro_x, gyro_y, gyro_z``: body rates, rad/s, body FLU; ``acc_x, acc_y, acc_z``:
specific force as an accelerometer reads it, m/s², body FLU, [0, 0, +9.81] level at
rest), each sensor's three columns together, and optionally more columns, which readers
keep as extras. Readers find columns by header name, so their order is free.

- `read_pose_log` reads and fully checks one; `PoseLogWriter` writes one row by row, every
  row on disk as it is recorded (`write_pose_log` a whole `PoseLog`).
- `read_external_pose` reads the pose columns of a motion-capture file with the same header
  names (``--pose``): rotor columns may be absent, and rows are left for the caller to
  clean.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.formats.parsed_log import Series

from mavsysid.errors import InputError, LogFormatError

__all__ = [
    "ACCEL_COLUMNS", "GYRO_COLUMNS", "IMU_COLUMNS", "POSE_COLUMNS", "QUATERNION_TOLERANCE",
    "ROTOR_COLUMN", "PoseLog", "PoseLogWriter",
    "TruncatedLogWarning", "check_positive_count", "parse_plain_rows", "read_external_pose",
    "read_pose_log", "read_text_file", "rotor_columns", "write_pose_log",
]

#: Required leading columns of a pose log, in the order the writer emits them.
POSE_COLUMNS: tuple[str, ...] = ("t", "x", "y", "z", "qw", "qx", "qy", "qz")

#: Optional IMU columns: body rates (rad/s) and specific force (m/s²), body FLU.
GYRO_COLUMNS: tuple[str, ...] = ("gyro_x", "gyro_y", "gyro_z")
ACCEL_COLUMNS: tuple[str, ...] = ("acc_x", "acc_y", "acc_z")
IMU_COLUMNS: tuple[str, ...] = GYRO_COLUMNS + ACCEL_COLUMNS

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
    """Names of the rotor-speed columns of a ``k``-rotor vehicle: ``("n1", …, "nk")``.

    Parameters
    ----------
    k : int
        Number of rotors.
    """
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
    gyro : ndarray, shape (N, 3), or None
        Body rates, rad/s, body FLU (columns ``gyro_x, gyro_y, gyro_z``); None without.
    accel : ndarray, shape (N, 3), or None
        Specific force, m/s², body FLU, as an accelerometer reads it: [0, 0, +9.81] level
        at rest (columns ``acc_x, acc_y, acc_z``); None without.
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    path: Path | None = None
    gyro: np.ndarray | None = None
    accel: np.ndarray | None = None

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
            "gyro": None if self.gyro is None else _frozen(self.gyro, (n, 3), "gyro",
                                                           f"(N, 3), N = {n}"),
            "accel": None if self.accel is None else _frozen(self.accel, (n, 3), "accel",
                                                             f"(N, 3), N = {n}"),
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
        """The samples with ``t0 <= t <= t1`` (s) as a new `PoseLog`, possibly empty.

        Parameters
        ----------
        t0, t1 : float
            First and last time kept, s.
        """
        if not t1 >= t0:
            raise ValueError(f"slice_time needs t0 <= t1, got t0={t0}, t1={t1}")
        i, j = np.searchsorted(self.t, t0, "left"), np.searchsorted(self.t, t1, "right")
        return PoseLog(self.t[i:j], self.position[i:j], self.quaternion[i:j],
                       self.rotor_speeds[i:j], {c: v[i:j] for c, v in self.extra.items()},
                       self.path, None if self.gyro is None else self.gyro[i:j],
                       None if self.accel is None else self.accel[i:j])


def read_text_file(path: Path, encoding: str = "utf-8") -> str:
    """The text of a file; anything unreadable is a one-line `LogFormatError`.

    Parameters
    ----------
    path : Path
        The file.
    encoding : str
        Its text encoding.
    """
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
    import pandas as pd  # its import costs the streamer's start a third of a second

    try:
        frame = pd.read_csv(io.StringIO(text), header=None, usecols=columns, dtype=np.float64,
                            na_filter=False, quoting=csv.QUOTE_NONE, engine="c")
    except ValueError:  # pandas' ParserError and EmptyDataError are ValueErrors
        return None
    return frame.to_numpy() if columns is None else frame[list(columns)].to_numpy()


def _is_float(text: str) -> bool:
    """Whether Python's float parses a CSV field."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _is_number(text: str) -> bool:
    """Whether a CSV field is a number, as numpy's loadtxt parses it."""
    return _is_float(text) and "_" not in text  # float() accepts digit separators, loadtxt not


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
        Quaternions renormalised (norm errors up to 1e-3 are accepted); the IMU columns,
        where present, as ``gyro`` and ``accel``.

    Raises
    ------
    LogFormatError
        One line naming the file, and the line number and column where they apply (an
        IMU sensor with only some of its three columns too).

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
    imu = _imu_columns(path, names)
    known = set(cols.values()) | {j for group in imu.values() for j in group}
    return PoseLog(
        t=data[:, cols["t"]],
        position=data[:, [cols[c] for c in POSE_COLUMNS[1:4]]],
        quaternion=q,
        rotor_speeds=data[:, [cols[c] for c in cols if c not in POSE_COLUMNS]],
        extra={names[j]: data[:, j] for j in range(ncol) if j not in known},
        path=path,
        gyro=data[:, imu["gyro"]] if "gyro" in imu else None,
        accel=data[:, imu["accel"]] if "accel" in imu else None,
    )


def _imu_columns(path: Path, names: list[str]) -> dict[str, list[int]]:
    """Header indices of each IMU sensor present ("gyro", "accel"): all three or none."""
    found = {}
    for sensor, columns in (("gyro", GYRO_COLUMNS), ("accel", ACCEL_COLUMNS)):
        present = [c for c in columns if c in names]
        if present and len(present) < 3:
            missing = ", ".join(c for c in columns if c not in names)
            raise LogFormatError(f"{path}: IMU column(s) {', '.join(present)} without "
                                 f"{missing}; a sensor's three columns go together")
        if present:
            found[sensor] = [names.index(c) for c in columns]
    return found


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


def _missing_columns(path: Path, kind: str, missing: list[str], names: list[str]) -> str:
    """One line naming each missing column and the header's column it may have become."""
    import difflib

    spare = [c for c in names if c not in POSE_COLUMNS and not ROTOR_COLUMN.fullmatch(c)]
    shown = []
    for column in missing:
        close = difflib.get_close_matches(column, spare, n=1, cutoff=0.5) or [
            c for c in spare if c.lower().replace("_", "") == column]
        shown.append(f"{column} (found {close[0]!r} instead?)" if close else column)
    other = f"; other columns: {', '.join(spare)}" if spare else ""
    return f"{path}: missing {kind} column(s) {', '.join(shown)}{other}"


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
        raise LogFormatError(_missing_columns(path, "required", missing, names))
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


def read_external_pose(path: Path) -> Series:
    """Read the pose columns of a motion-capture CSV file (other columns are ignored).

    Parameters
    ----------
    path : Path
        CSV text with a header naming at least ``t, x, y, z, qw, qx, qy, qz``.

    Returns
    -------
    Series
        Times on the motion-capture clock, s, and the pose (m = 7), as in the file (rows
        with NaN or out of order are left for `repair_samples` to report).

    Raises
    ------
    LogFormatError
        A missing column, a short row or a field that is not a number, with its line.
    """
    text = read_text_file(path, "utf-8-sig")
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise LogFormatError(f"{path}: no header row (expected {', '.join(POSE_COLUMNS)})")
    names = [c.strip() for c in next(csv.reader([lines[0]]))]
    missing = [c for c in POSE_COLUMNS if c not in names]
    if missing:
        raise LogFormatError(_missing_columns(path, "pose", missing, names))
    index = [names.index(c) for c in POSE_COLUMNS]
    rows = [line for line in lines[1:] if line.strip()]
    if not rows:
        raise LogFormatError(f"{path}: no samples, only a header row")
    data = None
    if all(line.count(",") == len(names) - 1 for line in rows):
        data = parse_plain_rows("\n".join(rows), index)
    if data is None:  # not plain numbers, or a bad row: parse field by field
        data = _parse_fields(path, lines, len(names), index)
    return Series(data[:, 0], data[:, 1:], f"pose of {path.name}")


def _parse_fields(path: Path, lines: list[str], ncol: int, index: list[int]) -> np.ndarray:
    """The columns ``index`` of the data rows, by Python's float; raise at a bad row."""
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != ncol:
            raise LogFormatError(f"{path}: line {number} has {len(fields)} fields, the header "
                                 f"has {ncol}")
        try:
            rows.append([float(fields[j]) for j in index])
        except ValueError:
            bad = next(fields[j].strip() for j in index if not _is_float(fields[j]))
            raise LogFormatError(f"{path}: line {number}: {bad[:24]!r} is not a number") from None
    return np.array(rows, dtype=float)


# --- writing -----------------------------------------------------------------------------

# Fixed point per column group, finer than any sensor: t 1e-6 s, position 1e-7 m,
# quaternion 1e-9, rotor speed 1e-4 rad/s. Extras have unknown units: 10 significant digits.
_FMT_T, _FMT_POS, _FMT_QUAT, _FMT_ROTOR, _FMT_EXTRA = "%.6f", "%.7f", "%.9f", "%.4f", "%.10g"
# IMU: 1e-7 rad/s, 1e-7 m/s², far below any MEMS sensor's resolution.
_FMT_IMU = "%.7f"
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
        Further columns, written after the rotor speeds (and the IMU).
    overwrite : bool, keyword-only
        Replace an existing file; otherwise that is an `InputError`, so that a new
        recording never destroys a flown one.
    imu : bool, keyword-only
        Write the IMU columns (`IMU_COLUMNS`) after the rotor speeds: every row then takes
        a ``gyro`` and an ``accel``.

    Rows are flushed as written, to survive a crash of this process; `close` also
    ``fsync``s. Each row is checked first (shapes, finite values, unit quaternion, ``t``
    increasing by at least the written 1e-6 s; else ``ValueError``), so the file always
    reads back. Attributes: ``path``, ``columns`` (the header), ``rows_written``.
    """

    def __init__(self, path: str | Path, rotor_count: int, extra_columns: Iterable[str] = (),
                 *, overwrite: bool = False, imu: bool = False) -> None:
        check_positive_count(rotor_count, "rotor_count")
        extras = tuple(extra_columns)
        taken = set(POSE_COLUMNS) | set(IMU_COLUMNS)
        for c in extras:
            if not isinstance(c, str) or not c or _BAD_NAME_RE.search(c):
                raise ValueError(f"extra column name {c!r} must be non-empty text without "
                                 "whitespace, commas or quotes")
            if c in taken or ROTOR_COLUMN.fullmatch(c):
                raise ValueError(f"extra column name {c!r} is reserved or repeated")
            taken.add(c)
        self.path, self.rotor_count, self.extra_columns = Path(path), rotor_count, extras
        self.imu = bool(imu)
        imu_columns = IMU_COLUMNS if self.imu else ()
        self.columns = POSE_COLUMNS + rotor_columns(rotor_count) + imu_columns + extras
        fmts = [_FMT_T, *[_FMT_POS] * 3, *[_FMT_QUAT] * 4, *[_FMT_ROTOR] * rotor_count,
                *[_FMT_IMU] * len(imu_columns)]
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
              extra: Mapping[str, float] | None = None, *, gyro: Any = None,
              accel: Any = None) -> None:
        """Write one sample: t (s), position (3,) m, quaternion (4,) [w,x,y,z], speeds (k,) rad/s.

        ``extra`` maps every name of ``extra_columns`` to a float.

        Parameters
        ----------
        t : float
            Time, s.
        position : array_like, shape (3,)
            Position, m, world ENU.
        quaternion : array_like, shape (4,)
            Attitude [w, x, y, z], body → world.
        rotor_speeds : array_like, shape (k,)
            Rotor speeds, rad/s.
        extra : Mapping of str to float, optional
            One value per extra column.
        gyro, accel : array_like, shape (3,), keyword-only
            With ``imu``: body rates (rad/s) and specific force (m/s²), body FLU.
        """
        self._check_open()
        pos, quat, rot = (np.asarray(v, dtype=np.float64)
                          for v in (position, quaternion, rotor_speeds))
        imu = self._imu_values(gyro, accel, 1)
        ex = {} if extra is None else extra
        if (np.ndim(t) == 0 and pos.shape == (3,) and quat.shape == (4,)
                and rot.shape == (self.rotor_count,) and ex.keys() == set(self.extra_columns)
                and all(isinstance(v, float | int) or np.ndim(v) == 0 for v in ex.values())):
            # Fast path on plain floats: a recorder calls this at every sample.
            values = [float(t), *pos.tolist(), *quat.tolist(), *rot.tolist(),
                      *imu.ravel().tolist(), *(float(ex[c]) for c in self.extra_columns)]
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
                        quat[None], rot[None], {c: np.ravel(v) for c, v in ex.items()},
                        gyro=None if gyro is None else imu[:, :3],
                        accel=None if accel is None else imu[:, 3:])

    def _imu_values(self, gyro: Any, accel: Any, n: int) -> np.ndarray:
        """The IMU block, shape (n, 6) (n, 0 without ``imu``), or a ValueError."""
        if not self.imu:
            if gyro is not None or accel is not None:
                raise ValueError("gyro and accel need a writer made with imu=True")
            return np.empty((n, 0))
        if gyro is None or accel is None:
            raise ValueError("a writer made with imu=True needs gyro and accel on every row")
        block = [np.asarray(v, dtype=np.float64).reshape(-1, 3) if np.size(v) == 3 * n
                 else np.asarray(v, dtype=np.float64) for v in (gyro, accel)]
        for name, value in zip(("gyro", "accel"), block, strict=True):
            if value.shape != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3) (or (3,) for one row), "
                                 f"got {value.shape}")
        return np.hstack(block)

    def write_rows(self, t: Any, position: Any, quaternion: Any, rotor_speeds: Any,
                   extra: Mapping[str, Any] | None = None, *, gyro: Any = None,
                   accel: Any = None) -> None:
        """Write N samples: t (N,) s, position (N, 3) m, quaternion (N, 4), speeds (N, k) rad/s.

        ``extra`` maps every name of ``extra_columns`` to an array of shape (N,).

        Parameters
        ----------
        t : array_like, shape (N,)
            Times, s.
        position : array_like, shape (N, 3)
            Positions, m, world ENU.
        quaternion : array_like, shape (N, 4)
            Attitudes [w, x, y, z], body → world.
        rotor_speeds : array_like, shape (N, k)
            Rotor speeds, rad/s.
        extra : Mapping of str to array_like, optional
            One array of shape (N,) per extra column.
        gyro, accel : array_like, shape (N, 3), keyword-only
            With ``imu``: body rates (rad/s) and specific force (m/s²), body FLU.
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
        cols.append(self._imu_values(gyro, accel, n))
        extra = extra or {}
        if extra.keys() != set(self.extra_columns):
            raise ValueError(f"extra values must be exactly {list(self.extra_columns)}, "
                             f"got {sorted(extra)}")
        for c in self.extra_columns:
            cols.append(np.asarray(extra[c], dtype=np.float64).reshape(-1, 1))
            if cols[-1].shape != (n, 1):
                raise ValueError(f"extra[{c!r}] must have shape ({n},), got {np.shape(extra[c])}")
        if n:
            self._write_block(np.hstack(cols), t)

    def _write_block(self, block: np.ndarray, t: np.ndarray) -> None:
        """Check a block of rows (finite, unit quaternions, t increasing) and write it."""
        bad = ~np.isfinite(block)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(f"{self.columns[j]} of sample {i} is {block[i, j]}; "
                             "a pose log holds finite values only")
        norm_err = np.abs(np.linalg.norm(block[:, 4:8], axis=1) - 1.0)
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
        for i in range(0, t.shape[0], _CHUNK_ROWS):
            part = block[i:i + _CHUNK_ROWS]
            self._file.write((self._fmt * len(part)) % tuple(part.ravel().tolist()))
        self._emit("", t.shape[0], float(np.round(t[-1], 6)))

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
    """Write a whole `PoseLog` to ``path`` with a `PoseLogWriter`; return the path.

    Parameters
    ----------
    path : str or Path
        The pose log to write.
    log : PoseLog
        The samples.
    overwrite : bool
        Replace an existing file (else an existing file is an error).
    """
    imu = log.gyro is not None or log.accel is not None
    if imu and (log.gyro is None or log.accel is None):
        raise ValueError("a pose log holds the gyro and the accelerometer together")
    with PoseLogWriter(path, log.rotor_count, log.extra, overwrite=overwrite, imu=imu) as w:
        w.write_rows(log.t, log.position, log.quaternion, log.rotor_speeds, log.extra,
                     gyro=log.gyro, accel=log.accel)
    return w.path
