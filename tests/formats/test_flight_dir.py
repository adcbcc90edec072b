"""Tests of the flight-directory files: meta.json and new flight directories."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from mavsysid.formats import flight_dir
from mavsysid.formats.flight_dir import new_flight_dir, read_meta, write_meta

from mavsysid.errors import InputError, LogFormatError


def test_meta_round_trip_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """write_meta round-trips (numpy values included) and an aborted write keeps the old file."""
    path = tmp_path / "flight" / "meta.json"
    meta = {"vehicle": "firefly", "rate_hz": np.float64(100.0), "k": np.int64(6),
            "J": np.array([0.03, 0.04, 0.09]), "log": Path("pose.csv")}
    write_meta(path, meta)
    assert read_meta(path) == {"vehicle": "firefly", "rate_hz": 100.0, "k": 6,
                               "J": [0.03, 0.04, 0.09], "log": "pose.csv"}
    assert path.read_text().startswith("{\n  ")

    def abort(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(flight_dir.os, "replace", abort)
    with pytest.raises(KeyboardInterrupt):
        write_meta(path, {"vehicle": "other"})
    monkeypatch.undo()
    with pytest.raises(TypeError):
        write_meta(path, {"bad": object()})
    with pytest.raises(ValueError):
        write_meta(path, {"bad": float("nan")})
    assert read_meta(path)["vehicle"] == "firefly"
    assert sorted(os.listdir(path.parent)) == ["meta.json"]


@pytest.mark.parametrize(
    ("content", "fragment"),
    [(None, "No such file"), ('{"a": 1,\n "b": }', "line 2"), ("[1, 2]", "JSON object")],
)
def test_read_meta_errors(tmp_path: Path, content: str | None, fragment: str) -> None:
    """A missing, malformed or non-object meta.json is a one-line LogFormatError."""
    path = tmp_path / "meta.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(LogFormatError, match=fragment) as info:
        read_meta(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_new_flight_dir_is_unique(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Default names are the timestamp, then -2, -3, …; an explicit existing name is an error."""
    monkeypatch.setattr(flight_dir, "_timestamp", lambda: "20240102-030405")
    root = tmp_path / "logs"
    made = [new_flight_dir(root) for _ in range(3)]
    assert [p.name for p in made] == ["20240102-030405", "20240102-030405-2",
                                      "20240102-030405-3"]
    assert all(p.is_dir() and not any(p.iterdir()) for p in made)
    assert new_flight_dir(root, "hover") == root / "hover"
    with pytest.raises(InputError, match="already exists") as info:
        new_flight_dir(root, "hover")
    assert "\n" not in str(info.value)
    for bad in ("a/b", "..", ""):
        with pytest.raises(InputError, match="plain directory name"):
            new_flight_dir(root, bad)


def test_new_flight_dir_default_name_is_local_time(tmp_path: Path) -> None:
    """Without monkeypatching, the default name has the %Y%m%d-%H%M%S form."""
    name = new_flight_dir(tmp_path).name
    assert len(name) == 15 and name[8] == "-" and name.replace("-", "").isdigit()


def test_meta_json_is_plain_json(tmp_path: Path) -> None:
    """meta.json is ordinary indented JSON any tool can read."""
    write_meta(tmp_path / "meta.json", {"a": [1, 2], "b": {"c": None}})
    assert json.loads((tmp_path / "meta.json").read_text()) == {"a": [1, 2], "b": {"c": None}}
