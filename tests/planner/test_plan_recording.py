"""Tests of the plan's Rerun recording, read back with rerun's own RRD reader."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.recording import (
    APPLICATION_ID,
    PATH_RATE,
    recording_id_for,
    time_colors,
    write_plan_rrd,
)
from mavsysid.vehicle.config import PARAMETER_NAMES
from rerun.chunk import RrdReader
from scipy.spatial.transform import Rotation

from tests.support.plans import fake_plan
from tests.support.rrd import series, temporal_rows

SIGMA = [f"/planner/{kind}/{name}" for kind in ("sigma", "relative_sigma")
         for name in PARAMETER_NAMES]
ENTITIES = ["/planner/graph/vertices", "/planner/graph/edges", "/planner/graph/path",
          "/planner/path", "/planner/vehicle", "/planner/inertia_covariance",
          "/planner/inertia_ellipsoids", *SIGMA]


def planner_entities(path: Path) -> set[str]:
    """Entities under /planner (rerun adds its own, such as /__properties)."""
    return {c.entity_path for c in RrdReader(path).stream()
            if c.entity_path.startswith("/planner/")}


def static_cell(path: Path, entity: str, column: str) -> list[Any]:
    """The one static value of an entity's component column."""
    (chunk,) = RrdReader(path).stream().filter(content=entity, is_static=True)
    return chunk.to_record_batch().column(column).to_pylist()[0]


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, PlanResult]:
    """A recording of the default fake plan, with the plan."""
    result = fake_plan()
    path = tmp_path_factory.mktemp("rrd") / "plan.rrd"
    write_plan_rrd(path, result)
    return path, result


def test_recording_identity(written):
    """One recording, app id 'mavsysid', id derived from kind, vehicle and settings."""
    path, result = written
    (store,) = RrdReader(path).recordings()
    assert store.application_id == APPLICATION_ID
    assert store.recording_id == recording_id_for(result)
    other = replace(result, settings=replace(result.settings, seed=2))
    assert recording_id_for(other) != recording_id_for(result)


def test_documented_entities_and_time_points(written):
    """Exactly the documented entities; σ series have one point per σ sample."""
    path, result = written
    assert planner_entities(path) == set(ENTITIES)
    rows = temporal_rows(path)
    assert {rows[e] for e in SIGMA} == {result.sigma_times.size}
    expected = int(np.ceil(result.trajectory.duration * PATH_RATE)) + 1
    assert rows["/planner/vehicle"] == expected


def test_graph_counts(written):
    """One point per vertex, one strip per edge path, one point per chosen vertex."""
    path, result = written
    graph = result.graph
    assert len(static_cell(path, "/planner/graph/vertices", "Points3D:positions")) == \
        len(graph.vertices)
    strips = static_cell(path, "/planner/graph/edges", "LineStrips3D:strips")
    assert [len(s) for s in strips] == [len(p) for p in graph.edge_paths]
    chosen = static_cell(path, "/planner/graph/path", "Points3D:positions")
    np.testing.assert_allclose(chosen, graph.vertices[graph.path, :3], rtol=1e-6)


def test_path_is_coloured_by_time(written):
    """The path is short strips whose colours run along the time colormap, start to end."""
    path, result = written
    strips = static_cell(path, "/planner/path", "LineStrips3D:strips")
    colors = static_cell(path, "/planner/path", "LineStrips3D:colors")
    assert len(strips) == len(colors) == int(np.ceil(result.trajectory.duration * PATH_RATE))
    first, last = time_colors(np.array([0.0, 1.0]))
    rgb = [(c >> 24, (c >> 16) & 255, (c >> 8) & 255) for c in colors]
    assert np.abs(np.subtract(rgb[0], first)).max() <= 3
    assert np.abs(np.subtract(rgb[-1], last)).max() <= 3
    np.testing.assert_allclose(strips[0][0], result.trajectory.flat_outputs([0.0]).position[0],
                               atol=1e-6)


def test_sigma_series_hold_the_prediction(written):
    """planner/sigma/<name> is the predicted σ (SI); relative_sigma is 100 σ/|θ nominal|."""
    path, result = written
    for j, name in enumerate(PARAMETER_NAMES):
        t, sigma = series(path, f"/planner/sigma/{name}")
        _, relative = series(path, f"/planner/relative_sigma/{name}")
        np.testing.assert_allclose(t, result.sigma_times, atol=1e-9)
        np.testing.assert_array_equal(sigma, result.predicted_sigma[:, j])
        np.testing.assert_allclose(relative, 100.0 * sigma / result.config.theta[j], rtol=1e-12)


def test_final_inertia_ellipsoid_is_the_covariance_block(written):
    """R diag(half_size²) Rᵀ reproduces the predicted 3×3 inertia covariance."""
    path, result = written
    (half,) = static_cell(path, "/planner/inertia_covariance", "Ellipsoids3D:half_sizes")
    (xyzw,) = static_cell(path, "/planner/inertia_covariance", "Ellipsoids3D:quaternions")
    rotation = Rotation.from_quat(xyzw).as_matrix()
    rebuilt = rotation @ np.diag(np.square(half)) @ rotation.T
    block = result.predicted_covariance[3:, 3:]
    np.testing.assert_allclose(rebuilt, block, rtol=1e-4, atol=1e-6 * np.abs(block).max())


def test_inertia_ellipsoids_along_the_path(written):
    """Five ellipsoids at planned positions, half sizes 0.5 m × σ_j / j_j, shrinking in time."""
    path, result = written
    centers = np.array(static_cell(path, "/planner/inertia_ellipsoids", "Ellipsoids3D:centers"))
    half = np.array(static_cell(path, "/planner/inertia_ellipsoids", "Ellipsoids3D:half_sizes"))
    chosen = [0, 6, 12, 18, 24]
    t = result.sigma_times[chosen]
    np.testing.assert_allclose(centers, result.trajectory.flat_outputs(t).position, atol=1e-6)
    expected = 0.5 * result.predicted_sigma[chosen, 3:] / result.config.theta[3:]
    np.testing.assert_allclose(half, expected, rtol=1e-6)
    assert np.all(np.diff(half, axis=0) < 0.0)


def test_without_sigma_history_only_the_final_ellipsoid(tmp_path):
    """With no σ history there are no σ series and no ellipsoids along the path."""
    path = tmp_path / "p.rrd"
    write_plan_rrd(path, fake_plan(history=0))
    assert planner_entities(path) == set(ENTITIES) - set(SIGMA) - {"/planner/inertia_ellipsoids"}


def test_file_is_complete_and_alone_on_return(written):
    """On return the file is finalised with a blueprint, and no temporary remains."""
    path, _ = written
    assert len(RrdReader(path).store()) > 0
    assert os.listdir(path.parent) == [path.name]
    assert RrdReader(path).blueprints()


def test_failed_write_keeps_previous_file(tmp_path):
    """When logging fails midway, the previous recording survives and no temporary is left."""
    path = tmp_path / "p.rrd"
    path.write_bytes(b"previous")
    result = fake_plan()
    bad = replace(result, predicted_sigma=result.predicted_sigma[:-1])
    with pytest.raises(ValueError):
        write_plan_rrd(path, bad)
    assert path.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["p.rrd"]
