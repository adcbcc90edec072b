"""Tests of the pose log format (pose.csv), meta.json and flight directories."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from mavsysid.formats.poselog import (
    POSE_COLUMNS,
    PoseLog,
    PoseLogWriter,
    TruncatedLogWarning,
    read_pose_log,
    rotor_columns,
    write_pose_log,
)

from mavsysid.errors import InputError, LogFormatError

EXTRAS = ("x_ref", "y_ref", "z_ref", "yaw_ref")


def make_samples(n: int, k: int, extras: tuple[str, ...] = (), seed: int = 0) -> dict:
    """Random but valid samples: increasing t at ~100 Hz, unit quaternions, hover-ish speeds."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return {
        "t": 12.5 + np.cumsum(rng.uniform(0.005, 0.015, size=n)),
        "position": rng.normal(scale=3.0, size=(n, 3)),
        "quaternion": q / np.linalg.norm(q, axis=1, keepdims=True),
        "rotor_speeds": rng.uniform(300.0, 838.0, size=(n, k)),
        "extra": {c: rng.normal(scale=10.0 ** rng.integers(-3, 4), size=n) for c in extras},
    }


def write_samples(path: Path, s: dict, extras: tuple[str, ...] = ()) -> Path:
    """Write samples with write_rows and return the path."""
    with PoseLogWriter(path, s["rotor_speeds"].shape[1], extras) as w:
        w.write_rows(s["t"], s["position"], s["quaternion"], s["rotor_speeds"],
                     s["extra"] or None)
    return path


def assert_matches(log: PoseLog, s: dict) -> None:
    """The log holds the samples to the stated write precision."""
    np.testing.assert_allclose(log.t, s["t"], rtol=0, atol=5e-7 + 1e-12)
    np.testing.assert_allclose(log.position, s["position"], rtol=0, atol=5e-8 + 1e-12)
    np.testing.assert_allclose(log.quaternion, s["quaternion"], rtol=0, atol=2e-9)
    np.testing.assert_allclose(log.rotor_speeds, s["rotor_speeds"], rtol=0, atol=5e-5 + 1e-9)
    assert list(log.extra) == list(s["extra"])
    for c, v in s["extra"].items():
        np.testing.assert_allclose(log.extra[c], v, rtol=6e-10, atol=0)


def header_and_rows(k: int = 4, n: int = 5) -> tuple[list[str], list[list[str]]]:
    """A small valid table as strings, to be corrupted by a test."""
    s = make_samples(n, k, seed=3)
    cols = [s["t"][:, None], s["position"], s["quaternion"], s["rotor_speeds"]]
    rows = [[repr(v) for v in r] for r in np.hstack(cols).tolist()]
    return list(POSE_COLUMNS + rotor_columns(k)), rows


def csv_text(header: list[str], rows: list[list[str]], end: str = "\n") -> str:
    """Join a header and rows as CSV text."""
    return "\n".join(",".join(r) for r in [header, *rows]) + end


def test_rotor_columns() -> None:
    """rotor_columns(k) names n1..nk in order."""
    assert rotor_columns(4) == ("n1", "n2", "n3", "n4")
    assert POSE_COLUMNS == ("t", "x", "y", "z", "qw", "qx", "qy", "qz")


@pytest.mark.parametrize("k", [4, 6])
@pytest.mark.parametrize("extras", [(), EXTRAS])
def test_round_trip_within_precision(tmp_path: Path, k: int, extras: tuple[str, ...]) -> None:
    """A written log reads back equal within the documented precision, extras included."""
    s = make_samples(500, k, extras, seed=k)
    path = write_samples(tmp_path / "f" / "pose.csv", s, extras)
    log = read_pose_log(path, rotor_count=k)
    assert_matches(log, s)
    assert (len(log), log.rotor_count, log.path) == (500, k, path)
    assert log.duration == pytest.approx(s["t"][-1] - s["t"][0], abs=1e-6)
    assert path.read_text().splitlines()[0].split(",") == [
        *POSE_COLUMNS, *rotor_columns(k), *extras]


def test_write_and_write_rows_produce_identical_files(tmp_path: Path) -> None:
    """Row-by-row and block writes of the same samples give byte-identical files."""
    s = make_samples(50, 6, EXTRAS, seed=1)
    write_samples(tmp_path / "block.csv", s, EXTRAS)
    with PoseLogWriter(tmp_path / "rows.csv", 6, EXTRAS) as w:
        for i in range(50):
            w.write(s["t"][i], s["position"][i], s["quaternion"][i], s["rotor_speeds"][i],
                    {c: v[i] for c, v in s["extra"].items()})
        assert w.rows_written == 50
    assert (tmp_path / "rows.csv").read_bytes() == (tmp_path / "block.csv").read_bytes()


def test_rows_readable_while_writer_open(tmp_path: Path) -> None:
    """Every written row is flushed: a second reader sees it before the writer closes."""
    s = make_samples(30, 4, seed=2)
    path = tmp_path / "pose.csv"
    with PoseLogWriter(path, 4) as w:
        assert path.read_text() == ",".join(POSE_COLUMNS + rotor_columns(4)) + "\n"
        w.write(s["t"][0], s["position"][0], s["quaternion"][0], s["rotor_speeds"][0])
        assert len(read_pose_log(path)) == 1
        w.write_rows(s["t"][1:], s["position"][1:], s["quaternion"][1:], s["rotor_speeds"][1:])
        assert len(read_pose_log(path)) == w.rows_written == 30
        assert not w.closed
    assert w.closed


@pytest.mark.parametrize("cut", [1, 7, 40, -1])
def test_truncated_last_row_is_dropped_with_warning(tmp_path: Path, cut: int) -> None:
    """A file cut inside its last row reads back the complete rows, with a TruncatedLogWarning."""
    s = make_samples(20, 6, EXTRAS, seed=4)
    path = write_samples(tmp_path / "pose.csv", s, EXTRAS)
    data = path.read_bytes()
    last_row_start = data.rstrip(b"\n").rfind(b"\n") + 1
    # cut = -1 keeps the last row up to and including its final comma (one empty field).
    end = data.rfind(b",") + 1 if cut == -1 else last_row_start + cut
    path.write_bytes(data[:end])
    with pytest.warns(TruncatedLogWarning, match=r"kept the 19 complete rows"):
        log = read_pose_log(path, rotor_count=6)
    assert_matches(log, {**s, **{key: s[key][:19] for key in s if key != "extra"},
                         "extra": {c: v[:19] for c, v in s["extra"].items()}})


def test_complete_last_row_without_newline_is_kept(tmp_path: Path) -> None:
    """A file whose complete last row merely lacks the final newline reads fully, silently."""
    header, rows = header_and_rows()
    path = tmp_path / "pose.csv"
    path.write_text(csv_text(header, rows, end=""))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(read_pose_log(path)) == len(rows)


def test_truncated_only_row_is_an_error(tmp_path: Path) -> None:
    """A file whose only data row is truncated has no samples: LogFormatError, not a warning."""
    header, rows = header_and_rows()
    path = tmp_path / "pose.csv"
    text = csv_text(header, rows[:1], end="")
    path.write_text(text[: len(text) - len(",".join(rows[0])) // 2])
    with pytest.raises(LogFormatError, match="no samples"):
        read_pose_log(path)


def _swap(rows: list[list[str]], i: int, j: int, value: str) -> list[list[str]]:
    rows[i][j] = value
    return rows


# (name, header/rows -> text, read_pose_log kwargs, fragments the message must contain)
MALFORMED = [
    ("empty", lambda h, r: "", {}, ["empty file"]),
    ("blank header", lambda h, r: "\n" + csv_text(h, r), {}, ["line 1 is empty"]),
    ("header only", lambda h, r: csv_text(h, []), {}, ["no samples"]),
    ("missing columns", lambda h, r: csv_text([c for c in h if c not in ("qw", "qy")],
                                              [[*x[:4], x[5], *x[7:]] for x in r]),
     {}, ["missing", "qw, qy"]),
    ("rotor count", lambda h, r: csv_text(h, r), {"rotor_count": 6},
     ["expected 6", "vehicle config", "found 4"]),
    ("rotor gap", lambda h, r: csv_text([*h[:-1], "n5"], r), {}, ["n1, n2, n3, n5"]),
    ("no rotors", lambda h, r: csv_text(h[:8], [x[:8] for x in r]), {}, ["no rotor"]),
    ("duplicate", lambda h, r: csv_text([*h, "x"], [[*x, "1"] for x in r]), {},
     ["column 13", "repeats the name 'x'"]),
    ("unnamed", lambda h, r: csv_text(["", *h], [["0", *x] for x in r]), {}, ["column 1"]),
    ("not a number", lambda h, r: csv_text(h, _swap(r, 1, 2, "1.2.3")), {},
     ["line 3", "'y'", "'1.2.3'"]),
    ("empty field", lambda h, r: csv_text(h, _swap(r, 3, 9, "")), {}, ["line 5", "'n2'"]),
    ("nan", lambda h, r: csv_text(h, _swap(r, 2, 9, "nan")), {}, ["line 4", "'n2'", "finite"]),
    ("inf", lambda h, r: csv_text(h, _swap(r, 0, 1, "-inf")), {}, ["line 2", "'x'", "finite"]),
    ("t repeated", lambda h, r: csv_text(h, _swap(r, 3, 0, r[2][0])), {}, ["line 5", "t ="]),
    ("t decreasing", lambda h, r: csv_text(h, _swap(r, 1, 0, "0.0")), {}, ["line 3", "t ="]),
    ("quaternion norm", lambda h, r: csv_text(h, _swap(r, 1, 4, "5.0")), {},
     ["line 3", "quaternion", "norm"]),
    ("short row", lambda h, r: csv_text(h, [*r[:2], r[2][:-1], *r[3:]]), {},
     ["line 4", "11 fields", "has 12"]),
    ("long last row with newline", lambda h, r: csv_text(h, [*r[:-1], [*r[-1], "1"]]), {},
     ["line 6", "13 fields"]),
    ("blank line", lambda h, r: csv_text(h, [*r[:2], [""], *r[2:]]), {}, ["line 4", "empty"]),
]


@pytest.mark.parametrize(("name", "build", "kwargs", "fragments"), MALFORMED,
                         ids=[m[0] for m in MALFORMED])
def test_malformed_file_raises_one_line_error(
    tmp_path: Path, name: str, build, kwargs: dict, fragments: list[str]
) -> None:
    """Each malformed file raises LogFormatError: one line naming the file, line and column."""
    header, rows = header_and_rows()
    path = tmp_path / "pose.csv"
    path.write_text(build(header, rows))
    with pytest.raises(LogFormatError) as info:
        read_pose_log(path, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(str(path))
    for fragment in fragments:
        assert fragment in message


def test_missing_and_unreadable_files(tmp_path: Path) -> None:
    """A missing file, a directory or binary junk is a one-line LogFormatError naming the path."""
    (tmp_path / "junk.csv").write_bytes(b"t,x\n\xff\xfe\x00")
    for path, fragment in ((tmp_path / "nope.csv", "No such file"), (tmp_path, "cannot read"),
                           (tmp_path / "junk.csv", "UTF-8")):
        with pytest.raises(LogFormatError, match=fragment) as info:
            read_pose_log(path)
        assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_small_quaternion_norm_error_is_normalised(tmp_path: Path) -> None:
    """Quaternions off unit norm by less than 1e-3 are accepted and normalised."""
    header, rows = header_and_rows()
    rows[2][4:8] = [repr(float(v) * (1 + 9e-4)) for v in rows[2][4:8]]
    path = tmp_path / "pose.csv"
    path.write_text(csv_text(header, rows))
    np.testing.assert_allclose(np.linalg.norm(read_pose_log(path).quaternion, axis=1), 1.0,
                               rtol=0, atol=1e-15)


def test_column_order_is_free(tmp_path: Path) -> None:
    """Columns are found by name: shuffled columns, interleaved extras, CRLF and BOM read alike."""
    s = make_samples(40, 6, ("vx", "mode"), seed=5)
    canonical = write_samples(tmp_path / "canonical.csv", s, ("vx", "mode"))
    lines = canonical.read_text().splitlines()
    table = np.array([line.split(",") for line in lines])
    order = np.random.default_rng(6).permutation(table.shape[1])
    shuffled = tmp_path / "shuffled.csv"
    shuffled.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(",".join(r) for r in table[:, order])
                         .encode() + b"\r\n")
    a, b = read_pose_log(canonical), read_pose_log(shuffled, rotor_count=6)
    for attr in ("t", "position", "quaternion", "rotor_speeds"):
        np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr))
    assert set(b.extra) == {"vx", "mode"}
    for c in a.extra:
        np.testing.assert_array_equal(a.extra[c], b.extra[c])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ({"position": np.zeros(2)}, r"position must have shape \(3,\)"),
        ({"rotor_speeds": np.zeros(6)}, r"rotor_speeds must have shape \(4,\)"),
        ({"t": np.array([1.0, 2.0])}, "t must be a scalar"),
        ({"extra": {"other": 1.0}}, "extra values must be exactly"),
        ({"position": [0.0, np.nan, 0.0]}, "y of sample 0 is nan"),
        ({"quaternion": [1.0, 0.1, 0.0, 0.0]}, "norm"),
        ({"t": 0.5}, "t must increase"),
        ({"t": 1.0000001}, "t must increase"),
    ],
)
def test_writer_rejects_invalid_rows(tmp_path: Path, args: dict, match: str) -> None:
    """Invalid rows raise ValueError before anything is written, so the file stays readable."""
    good = {"t": 1.0, "position": np.zeros(3), "quaternion": [1.0, 0, 0, 0],
            "rotor_speeds": np.full(4, 500.0), "extra": None}
    path = tmp_path / "pose.csv"
    with PoseLogWriter(path, 4) as w:
        w.write(**good)
        with pytest.raises(ValueError, match=match):
            w.write(**{**good, "t": 2.0, **args})
        assert w.rows_written == 1
    assert len(read_pose_log(path)) == 1


def test_writer_rejects_invalid_blocks(tmp_path: Path) -> None:
    """write_rows validates shapes, extras, finiteness and increasing t of the whole block."""
    s = make_samples(10, 4, ("vx",), seed=7)
    args = (s["t"], s["position"], s["quaternion"], s["rotor_speeds"])
    with PoseLogWriter(tmp_path / "pose.csv", 4, ("vx",)) as w:
        with pytest.raises(ValueError, match=r"rotor_speeds must have shape \(10, 4\)"):
            w.write_rows(*args[:3], s["rotor_speeds"][:, :3], s["extra"])
        with pytest.raises(ValueError, match=r"extra\['vx'\] must have shape \(10,\)"):
            w.write_rows(*args, {"vx": s["extra"]["vx"][:5]})
        with pytest.raises(ValueError, match="extra values must be exactly"):
            w.write_rows(*args)
        t = s["t"].copy()
        t[5] = t[4]
        with pytest.raises(ValueError, match="sample 5"):
            w.write_rows(t, *args[1:], s["extra"])
        w.write_rows(*args, s["extra"])
        with pytest.raises(ValueError, match="t must increase"):
            w.write_rows(*args, s["extra"])
        assert w.rows_written == 10
    with pytest.raises(ValueError, match="closed"):
        w.write_rows(*args, s["extra"])


@pytest.mark.parametrize("name", ["n1", "n7", "t", "qw", "a b", "a,b", ""])
def test_writer_rejects_bad_extra_names(tmp_path: Path, name: str) -> None:
    """Extra column names may not shadow required or rotor columns or break the CSV."""
    with pytest.raises(ValueError, match="extra column name"):
        PoseLogWriter(tmp_path / "pose.csv", 4, (name,))


def test_writer_never_replaces_a_recording_by_default(tmp_path: Path) -> None:
    """An existing pose log is an InputError unless overwrite=True; closing twice is harmless."""
    path = write_samples(tmp_path / "pose.csv", make_samples(5, 4))
    with pytest.raises(InputError, match="already exists"):
        PoseLogWriter(path, 4)
    assert len(read_pose_log(path)) == 5
    w = PoseLogWriter(path, 4, overwrite=True)
    w.close()
    w.close()
    with pytest.raises(ValueError, match="closed"):
        w.write(0.0, np.zeros(3), [1.0, 0, 0, 0], np.zeros(4))


def test_slice_time_and_immutability(tmp_path: Path) -> None:
    """slice_time keeps t0 <= t <= t1 (inclusive) across all columns; arrays are read-only."""
    s = make_samples(100, 4, ("vx",), seed=8)
    log = read_pose_log(write_samples(tmp_path / "pose.csv", s, ("vx",)))
    part = log.slice_time(log.t[10], log.t[20])
    assert len(part) == 11 and part.path == log.path and part.rotor_count == 4
    np.testing.assert_array_equal(part.rotor_speeds, log.rotor_speeds[10:21])
    np.testing.assert_array_equal(part.extra["vx"], log.extra["vx"][10:21])
    assert len(log.slice_time(0.0, 1.0)) == 0 and log.slice_time(0.0, 1.0).duration == 0.0
    with pytest.raises(ValueError, match="t0 <= t1"):
        log.slice_time(2.0, 1.0)
    with pytest.raises(ValueError, match="read-only"):
        log.position[0, 0] = 1.0
    with pytest.raises(ValueError, match=r"quaternion must have shape \(N, 4\)"):
        PoseLog(log.t, log.position, log.quaternion[:, :3], log.rotor_speeds)
    with pytest.raises(ValueError, match="strictly increasing"):
        PoseLog(log.t[::-1], log.position, log.quaternion, log.rotor_speeds)


def test_write_pose_log_round_trip(tmp_path: Path) -> None:
    """write_pose_log writes a PoseLog that reads back unchanged (already rounded values)."""
    s = make_samples(60, 6, EXTRAS, seed=9)
    log = read_pose_log(write_samples(tmp_path / "a.csv", s, EXTRAS)).slice_time(13.0, 13.3)
    again = read_pose_log(write_pose_log(tmp_path / "b.csv", log))
    for attr in ("t", "position", "rotor_speeds"):
        np.testing.assert_array_equal(getattr(again, attr), getattr(log, attr))
    np.testing.assert_allclose(again.quaternion, log.quaternion, rtol=0, atol=2e-9)
    assert list(again.extra) == list(EXTRAS)
