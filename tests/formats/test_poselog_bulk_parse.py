"""Tests of the bulk CSV parse (pandas' C parser) behind the pose log readers.

The readers parse plain decimal text with pandas and anything else field by field; the two
must agree on every field pandas accepts, or a file would read differently by its content.
"""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import numpy as np
import pytest
from mavsysid.formats.poselog import (
    PoseLog,
    parse_plain_rows,
    read_external_pose,
    read_pose_log,
    write_pose_log,
)

# The characters parse_plain_rows reads with pandas, weighted towards numbers.
_ALPHABET = "0123456789" + "eE.+- \t"
_WEIGHTS = [3] * 10 + [1] * 7


def _loadtxt_field(text: str) -> float | None:
    """The value numpy's loadtxt (the strict reader's reference) gives a field, or None."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            return float(np.loadtxt([f"0,{text}"], delimiter=",", comments=None, ndmin=2)[0, 1])
    except ValueError:
        return None


def _bits(value: float) -> int:
    return int(np.float64(value).view(np.int64))


def test_plain_fields_parse_as_loadtxt_and_float_do() -> None:
    """Every field pandas accepts has loadtxt's and float's value, to the bit; many are accepted."""
    rng = random.Random(17)
    accepted = 0
    for _ in range(1500):
        text = "".join(rng.choices(_ALPHABET, _WEIGHTS, k=rng.randint(0, 7)))
        data = parse_plain_rows(f"0,{text}\n", [1])
        if data is None:
            continue
        accepted += 1
        reference = _loadtxt_field(text)
        assert reference is not None, f"pandas accepts {text!r}, loadtxt does not"
        assert data.shape == (1, 1)
        assert _bits(data[0, 0]) == _bits(reference) == _bits(float(text)), text
    assert accepted > 300  # the comparison above ran on a real share of the fields


@pytest.mark.parametrize("text", ["nan", "-inf", "True", "false", "1_000", "1.5\r", "", "1.2.3"])
def test_anything_but_plain_numbers_is_left_to_the_caller(text: str) -> None:
    """nan, inf, words and malformed numbers give None (the caller parses field by field)."""
    assert parse_plain_rows(f"1.0,2.0\n3.0,{text}\n") is None


def test_columns_come_back_in_the_order_asked() -> None:
    """``columns`` picks and orders columns; None returns them all."""
    text = "1,2,3\n4,5,6"
    np.testing.assert_array_equal(parse_plain_rows(text, [2, 0]), [[3.0, 1.0], [6.0, 4.0]])
    np.testing.assert_array_equal(parse_plain_rows(text), [[1, 2, 3], [4, 5, 6]])


def _reference_rows(path: Path) -> np.ndarray:
    """All fields of a CSV's data rows by Python's float, the per-field reference."""
    lines = path.read_text().splitlines()[1:]
    return np.array([[float(f) for f in line.split(",")] for line in lines if line.strip()])


def test_both_readers_match_field_by_field_parsing(tmp_path: Path) -> None:
    """A written log reads to the bit as parsing every field with float does, in both readers."""
    rng = np.random.default_rng(3)
    n = 500
    q = rng.normal(size=(n, 4))
    log = PoseLog(np.cumsum(rng.uniform(0.001, 0.01, n)), rng.normal(scale=5.0, size=(n, 3)),
                  q / np.linalg.norm(q, axis=1, keepdims=True), rng.uniform(0, 900, (n, 4)),
                  {"vx": rng.normal(scale=1e-3, size=n)})
    path = write_pose_log(tmp_path / "pose.csv", log)
    ref = _reference_rows(path)
    got = read_pose_log(path, 4)
    norm = np.linalg.norm(ref[:, 4:8], axis=1, keepdims=True)
    np.testing.assert_array_equal(np.column_stack([got.t, got.position, got.rotor_speeds,
                                                   got.extra["vx"]]),
                                  ref[:, [0, 1, 2, 3, 8, 9, 10, 11, 12]])
    np.testing.assert_array_equal(got.quaternion, ref[:, 4:8] / norm)
    external = read_external_pose(path)
    np.testing.assert_array_equal(np.column_stack([external.t, external.values]), ref[:, :8])


def test_external_pose_with_nan_and_text_columns_reads_field_by_field(tmp_path: Path) -> None:
    """A motion-capture file with a dropout (nan) and a text column keeps its nan row."""
    path = tmp_path / "mocap.csv"
    path.write_text("t,x,y,z,qw,qx,qy,qz,body\n"
                    "0.0,1,2,3,1,0,0,0,drone\n"
                    "0.01,nan,nan,nan,nan,nan,nan,nan,drone\n"
                    "\n"
                    "0.02,1.5,2,3,1,0,0,0,drone\n")
    pose = read_external_pose(path)
    np.testing.assert_array_equal(pose.t, [0.0, 0.01, 0.02])
    assert np.isnan(pose.values[1]).all() and pose.values[2, 0] == 1.5
