"""The optional IMU columns of pose.csv: written, read back, refused in one line when wrong.

``gyro_x, gyro_y, gyro_z`` (rad/s) and ``acc_x, acc_y, acc_z`` (specific force, m/s²), body
FLU, on the pose rows. Fuzzed IMU fields (NaN, words, a sensor's column missing, junk
bytes) end in a one-line `LogFormatError` naming file, line and column, never a traceback.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from mavsysid.formats.poselog import (
    ACCEL_COLUMNS,
    GYRO_COLUMNS,
    IMU_COLUMNS,
    PoseLog,
    PoseLogWriter,
    TruncatedLogWarning,
    read_pose_log,
    write_pose_log,
)

from mavsysid.errors import LogFormatError


def _samples(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return {"t": 3.0 + np.cumsum(rng.uniform(0.002, 0.004, n)),
            "position": rng.normal(size=(n, 3)),
            "quaternion": q / np.linalg.norm(q, axis=1, keepdims=True),
            "rotor_speeds": rng.uniform(300.0, 800.0, (n, 4)),
            "gyro": rng.normal(scale=2.0, size=(n, 3)),
            "accel": rng.normal(scale=3.0, size=(n, 3)) + [0.0, 0.0, 9.81]}


def _write(path: Path, s: dict[str, np.ndarray], extras: tuple[str, ...] = ()) -> Path:
    with PoseLogWriter(path, 4, extras, imu=True) as writer:
        writer.write_rows(s["t"], s["position"], s["quaternion"], s["rotor_speeds"],
                          {c: np.zeros(s["t"].size) for c in extras} or None,
                          gyro=s["gyro"], accel=s["accel"])
    return path


def test_imu_columns_round_trip_and_leave_the_extras(tmp_path: Path) -> None:
    s = _samples(300)
    log = read_pose_log(_write(tmp_path / "pose.csv", s, ("x_ref",)), 4)
    np.testing.assert_allclose(log.gyro, s["gyro"], rtol=0, atol=5e-8 + 1e-12)
    np.testing.assert_allclose(log.accel, s["accel"], rtol=0, atol=5e-8 + 1e-12)
    assert list(log.extra) == ["x_ref"]
    header = (tmp_path / "pose.csv").read_text().split("\n")[0].split(",")
    assert header[8:18] == ["n1", "n2", "n3", "n4", *IMU_COLUMNS]
    # Sliced and written whole, the IMU goes along.
    part = log.slice_time(float(s["t"][10]), float(s["t"][20]))
    assert part.gyro.shape == (11, 3) and part.accel.shape == (11, 3)
    again = read_pose_log(write_pose_log(tmp_path / "again.csv", log), 4)
    np.testing.assert_array_equal(again.gyro, log.gyro)
    np.testing.assert_array_equal(again.accel, log.accel)


def test_row_by_row_writes_the_same_file(tmp_path: Path) -> None:
    s = _samples(20, seed=4)
    _write(tmp_path / "block.csv", s)
    with PoseLogWriter(tmp_path / "rows.csv", 4, imu=True) as writer:
        for i in range(20):
            writer.write(s["t"][i], s["position"][i], s["quaternion"][i], s["rotor_speeds"][i],
                         gyro=s["gyro"][i], accel=s["accel"][i])
    assert (tmp_path / "rows.csv").read_bytes() == (tmp_path / "block.csv").read_bytes()


def test_a_log_without_imu_columns_has_none(tmp_path: Path) -> None:
    s = _samples(5)
    with PoseLogWriter(tmp_path / "p.csv", 4) as writer:
        writer.write_rows(s["t"], s["position"], s["quaternion"], s["rotor_speeds"])
    log = read_pose_log(tmp_path / "p.csv", 4)
    assert log.gyro is None and log.accel is None


def test_gyro_alone_is_read(tmp_path: Path) -> None:
    """A file with the gyro's three columns and no accelerometer: gyro only."""
    s = _samples(5)
    path = _write(tmp_path / "p.csv", s)
    lines = path.read_text().split("\n")
    keep = [j for j, name in enumerate(lines[0].split(",")) if name not in ACCEL_COLUMNS]
    path.write_text("\n".join(",".join(line.split(",")[j] for j in keep) for line in lines
                              if line) + "\n")
    log = read_pose_log(path, 4)
    assert log.accel is None and log.gyro.shape == (5, 3)


@pytest.mark.parametrize("missing", ["gyro_y", "acc_z"])
def test_a_sensor_with_a_column_missing_is_refused(tmp_path: Path, missing: str) -> None:
    path = _write(tmp_path / "p.csv", _samples(5))
    lines = path.read_text().split("\n")
    j = lines[0].split(",").index(missing)
    path.write_text("\n".join(",".join(f for i, f in enumerate(line.split(",")) if i != j)
                              for line in lines if line) + "\n")
    with pytest.raises(LogFormatError, match=rf"p\.csv: IMU column\(s\) .* without {missing}; "
                                             "a sensor's three columns go together"):
        read_pose_log(path, 4)


@pytest.mark.parametrize("field", ["nan", "inf", "abc", "", "1e999", "0x1F", "1,5"])
@pytest.mark.parametrize("column", ["gyro_z", "acc_x"])
def test_a_bad_imu_field_is_named_with_file_line_and_column(tmp_path: Path, field: str,
                                                            column: str) -> None:
    path = _write(tmp_path / "pose.csv", _samples(6))
    lines = path.read_text().split("\n")
    j = lines[0].split(",").index(column)
    fields = lines[4].split(",")
    fields[j] = field
    lines[4] = ",".join(fields)
    path.write_text("\n".join(lines))
    with pytest.raises(LogFormatError) as caught:
        read_pose_log(path, 4)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message and "line 5" in message, message
    if field != "1,5":  # an extra comma is a field count, not a column
        assert repr(column) in message, message


def test_writer_refuses_missing_or_non_finite_imu_values(tmp_path: Path) -> None:
    s = _samples(3)
    with PoseLogWriter(tmp_path / "p.csv", 4, imu=True) as writer:
        with pytest.raises(ValueError, match="needs gyro and accel on every row"):
            writer.write(s["t"][0], s["position"][0], s["quaternion"][0], s["rotor_speeds"][0])
        bad = s["accel"].copy()
        bad[1, 2] = np.nan
        with pytest.raises(ValueError, match="acc_z of sample 1 is nan"):
            writer.write_rows(s["t"], s["position"], s["quaternion"], s["rotor_speeds"],
                              gyro=s["gyro"], accel=bad)
        with pytest.raises(ValueError, match=r"gyro must have shape \(3, 3\)"):
            writer.write_rows(s["t"], s["position"], s["quaternion"], s["rotor_speeds"],
                              gyro=s["gyro"][:, :2], accel=s["accel"])
    with PoseLogWriter(tmp_path / "q.csv", 4) as writer, \
            pytest.raises(ValueError, match="need a writer made with imu=True"):
        writer.write(s["t"][0], s["position"][0], s["quaternion"][0], s["rotor_speeds"][0],
                     gyro=s["gyro"][0], accel=s["accel"][0])
    for name in GYRO_COLUMNS[:1] + ACCEL_COLUMNS[:1]:
        with pytest.raises(ValueError, match="reserved or repeated"):
            PoseLogWriter(tmp_path / f"{name}.csv", 4, (name,))
    with pytest.raises(ValueError, match="gyro and the accelerometer together"):
        write_pose_log(tmp_path / "r.csv", PoseLog(s["t"], s["position"], s["quaternion"],
                                                   s["rotor_speeds"], gyro=s["gyro"]))


def test_fuzzed_imu_columns_read_or_refuse_in_one_line(tmp_path: Path) -> None:
    """200 seeded corruptions of the IMU fields and bytes of a clean log: read (and then
    finite, of the right shape) or refused in one line naming the file; nothing else."""
    clean = _write(tmp_path / "clean.csv", _samples(50, seed=2)).read_text()
    header = clean.split("\n")[0].split(",")
    imu = [header.index(c) for c in IMU_COLUMNS]
    words = ["nan", "-inf", "1e400", "true", "--", "", '"2"', "0x10", "1e-400", "٣", "+-1"]
    rng = np.random.default_rng(11)
    outcomes = []
    for case in range(200):
        lines = clean.split("\n")
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(1, len(lines) - 1))
            fields = lines[i].split(",")
            fields[imu[int(rng.integers(0, 6))]] = str(rng.choice(words))
            lines[i] = ",".join(fields)
        data = "\n".join(lines).encode()
        if case % 4 == 3:  # cut inside the IMU columns of a row, or junk appended
            data = data[:int(rng.integers(len(data) // 2, len(data)))] if case % 8 == 3 \
                else data + rng.bytes(int(rng.integers(1, 200)))
        path = tmp_path / f"c{case}.csv"
        path.write_bytes(data)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", TruncatedLogWarning)
                log = read_pose_log(path, 4)
        except LogFormatError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc), exc
            outcomes.append("refused")
            continue
        assert np.isfinite(log.gyro).all() and np.isfinite(log.accel).all()
        assert log.gyro.shape == log.accel.shape == (len(log), 3)
        outcomes.append("read")
    assert outcomes.count("refused") > 150 and "read" in outcomes
