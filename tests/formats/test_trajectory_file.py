"""Tests of the trajectory file (JSON)."""

from __future__ import annotations

import copy
import json
import math
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.flight.offline.excitation import excitation_trajectory
from mavsysid.formats.trajectory_file import (
    read_trajectory,
    trajectory_file_for,
    write_trajectory_file,
)
from mavsysid.planner.plan_file import plan_file_for, write_trajectory
from mavsysid.planner.plan_result import PlanResult
from mavsysid.vehicle.config import PARAMETER_NAMES, Limits, load_vehicle, vehicle_to_toml

from mavsysid.errors import InputError
from tests.support.plans import fake_plan


@pytest.fixture
def plan_file(tmp_path: Path) -> tuple[Path, PlanResult]:
    """A written trajectory file of `fake_plan`."""
    result = fake_plan()
    path = tmp_path / "calib.json"
    write_trajectory(path, result)
    return path, result


def test_round_trip_is_exact(plan_file):
    """Reading back gives the same segments bit for bit, and the plan's metadata."""
    path, result = plan_file
    read = read_trajectory(path)
    np.testing.assert_array_equal(read.trajectory.durations, result.trajectory.durations)
    np.testing.assert_array_equal(read.trajectory.position_coeffs,
                                  result.trajectory.position_coeffs)
    np.testing.assert_array_equal(read.trajectory.yaw_coeffs, result.trajectory.yaw_coeffs)
    assert read.kind == "dopt" and read.vehicle_name == "firefly"
    assert read.predicted_dopt == result.predicted_dopt
    assert read.box == result.settings.box
    assert read.start == (1.3, 1.0, 1.9, 0.0)
    assert read.limits_config() == result.config.limits


def test_document_follows_the_design(plan_file):
    """Segments hold 3×10 position and 6 yaw coefficients; every documented key is there."""
    path, result = plan_file
    doc = json.loads(path.read_text())
    assert doc["format"] == "mavsysid-trajectory" and doc["format_version"] == 1
    assert {len(s["yaw"]) for s in doc["segments"]} == {6}
    assert {(len(s["position"]), len(s["position"][0])) for s in doc["segments"]} == {(3, 10)}
    assert math.isclose(doc["duration"], sum(s["duration"] for s in doc["segments"]))
    assert set(doc["limits"]) == {f.name for f in fields(Limits)}
    assert set(doc["predicted_sigma"]) == {"t", *PARAMETER_NAMES}
    np.testing.assert_array_equal(doc["predicted_sigma"]["j_z"], result.predicted_sigma[:, 5])
    assert {"seed", "budget", "planning_time", "max_samples", "samples", "vertices", "edges",
            "beliefs", "elapsed", "time_to_first_solution"} <= set(doc["planner"])
    assert doc["software"]["name"] == "mavsysid"


def test_predicted_dopt_is_sixth_root_of_determinant(plan_file):
    """predicted_dopt is det(Σθ)^(1/6) of the stored 6×6 covariance, SI."""
    doc = json.loads(plan_file[0].read_text())
    sign, log_det = np.linalg.slogdet(np.array(doc["predicted_covariance"]))
    assert sign > 0.0
    assert math.isclose(doc["predicted_dopt"], math.exp(log_det / 6.0), rel_tol=1e-9)


def test_stored_vehicle_loads_back(plan_file, tmp_path):
    """vehicle.config_toml is the full configuration the flight was planned for."""
    path, result = plan_file
    toml = tmp_path / "planned.toml"
    toml.write_text(read_trajectory(path).vehicle_toml)
    assert load_vehicle(toml).theta.tolist() == result.config.theta.tolist()
    assert read_trajectory(path).vehicle_toml == vehicle_to_toml(result.config)


def test_unlimited_planning_time_is_null_and_json_is_strict(tmp_path):
    """An unlimited planning time is stored as null; the file holds no NaN or infinity."""
    path = tmp_path / "t.json"
    write_trajectory(path, fake_plan(planning_time=math.inf))

    def refuse(constant: str) -> float:
        raise AssertionError(f"non-JSON constant {constant}")

    assert json.loads(path.read_text(), parse_constant=refuse)["planner"]["planning_time"] is None


def test_excitation_exports_without_prediction(tmp_path):
    """The built-in figure exports in the same format, with null box, prediction and planner."""
    config = load_vehicle("quad_x")
    figure = excitation_trajectory()
    path = tmp_path / "figure.json"
    write_trajectory_file(path, trajectory_file_for(figure, config))
    read = read_trajectory(path)
    assert (read.kind, read.box, read.predicted_dopt) == ("excitation", None, None)
    assert read.raw["planner"] is None and read.vehicle_name == "quad_x"
    t = np.linspace(-1.0, figure.duration + 1.0, 777)
    np.testing.assert_array_equal(read.trajectory.flat_outputs(t).snap,
                                  figure.flat_outputs(t).snap)


def _set(doc: dict[str, Any], key: str, value: Any) -> None:
    """Set (or, for value ..., delete) a dotted key like 'segments.1.position'."""
    *parents, last = key.split(".")
    for part in parents:
        doc = doc[int(part)] if part.isdigit() else doc[part]
    if value is ...:
        del doc[last]
    else:
        doc[int(last) if last.isdigit() else last] = value


BAD = [
    ("format", "other-trajectory", "format"),
    ("format_version", 2, "format_version"),
    ("kind", ..., "kind"),
    ("segments", ..., "segments"),
    ("segments", [], "segments"),
    ("segments.1.position", [[0.0] * 10] * 2, "segments[1].position"),
    ("segments.2.position.1", [0.0] * 9, "segments[2].position[1]"),
    ("segments.1.yaw", [0.0] * 5, "segments[1].yaw"),
    ("segments.3.yaw.2", "x", "segments[3].yaw[2]"),
    ("segments.0.duration", -1.0, "segments[0].duration"),
    ("duration", 99.0, "duration"),
    ("vehicle.config_toml", ..., "vehicle.config_toml"),
    ("vehicle.config_toml", "mass = = 1", "vehicle.config_toml"),
    ("limits.rotor_speed_max", ..., "limits"),
    ("limits.speed_max", "fast", "limits.speed_max"),
    ("box", [2.0, -2.0, 0.5, -2.0, 2.0, 2.5], "box"),
    ("start", [0.0, 0.0, 1.0], "start"),
    ("start", [0.0, 0.0, 1.0, 0.0], "start"),
    ("predicted_dopt", -1.0, "predicted_dopt"),
    ("predicted_covariance", [[0.0] * 6] * 5, "predicted_covariance"),
    ("predicted_sigma.j_z", [1.0], "predicted_sigma.j_z"),
    ("planner", [1, 2], "planner"),
]


@pytest.mark.parametrize(("key", "value", "named"), BAD, ids=[f"{k}={v!r}"[:40] for k, v, _ in BAD])
def test_bad_document_is_one_line_naming_file_and_key(plan_file, key, value, named):
    """Each malformed key is an InputError of one line naming the file and that key."""
    path, _ = plan_file
    doc = json.loads(path.read_text())
    _set(doc, key, value)
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as error:
        read_trajectory(path)
    message = str(error.value)
    assert "\n" not in message and str(path) in message
    assert f": {named}:" in message


@pytest.mark.parametrize(("text", "named"), [
    ("{not json", "line 1"), ("[1, 2]", "document"),
])
def test_non_object_files_are_refused(tmp_path, text, named):
    """Text that is not JSON, or JSON that is not an object, is a one-line InputError."""
    path = tmp_path / "t.json"
    path.write_text(text)
    with pytest.raises(InputError, match=named):
        read_trajectory(path)


def test_non_finite_values_name_their_key(plan_file):
    """NaN and infinity (which Python's json writes) are refused at the key that holds them."""
    path, _ = plan_file
    doc = json.loads(path.read_text())
    doc["segments"][0]["position"][2][3] = math.nan
    doc["predicted_dopt"] = math.inf
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"segments\[0\]\.position\[2\]\[3\]: a finite"):
        read_trajectory(path)


def test_missing_file_is_input_error(tmp_path):
    """A missing file is a one-line InputError naming it."""
    with pytest.raises(InputError, match=r"nope\.json"):
        read_trajectory(tmp_path / "nope.json")


def test_invalid_document_is_not_written(tmp_path):
    """write_trajectory_file checks first: an unreadable document leaves no file behind."""
    doc = trajectory_file_for(excitation_trajectory(), load_vehicle("firefly"))
    broken = copy.deepcopy(doc)
    broken["segments"][1]["yaw"][0] = math.nan
    with pytest.raises(InputError, match=r"segments\[1\]\.yaw\[0\]"):
        write_trajectory_file(tmp_path / "t.json", broken)
    assert not any(tmp_path.iterdir())


def test_plan_file_for_has_prediction_trajectory_file_for_has_none():
    """Only a plan carries the predicted fields."""
    result = fake_plan()
    assert plan_file_for(result)["predicted_covariance"] is not None
    bare = trajectory_file_for(result.trajectory, result.config, kind="dopt")
    assert (bare["predicted_dopt"], bare["predicted_sigma"], bare["box"]) == (None, None, None)
