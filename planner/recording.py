"""A Rerun recording of a planned flight (``mavsysid plan --rrd FILE``).

Entities (positions in m, world ENU; time series on the ``time`` timeline, s from the
start of the flight):

- ``planner/graph/vertices`` (Points3D) and ``planner/graph/edges`` (LineStrips3D, one
  strip per feasible edge, sampled along it): the motion graph, static; logged only when
  the graph has vertices / edges. ``planner/graph/path`` (Points3D): the chosen vertices.
- ``planner/path`` (LineStrips3D, static): the planned flight sampled at 50 Hz as short
  strips coloured by time along a viridis-like colormap (dark blue at take-off, yellow
  at the end).
- ``planner/vehicle`` (Points3D): the reference position over time.
- ``planner/sigma/<name>`` (Scalars): predicted σ of each parameter, SI, and
  ``planner/relative_sigma/<name>``: the same relative to the nominal value, %.
- ``planner/inertia_covariance`` (Ellipsoids3D, static): the 1σ ellipsoid of the predicted
  final inertia covariance (the 3×3 (j_x, j_y, j_z) block), in its own frame whose axes
  are j_x, j_y, j_z in kg·m², centred at 0: half sizes are the square roots of the
  eigenvalues, the rotation that of the eigenvectors. It is shown in its own view
  because it is far too small to see at the scale of metres.
- ``planner/inertia_ellipsoids`` (Ellipsoids3D, static): the paper's Fig. 2, at up to
  five instants evenly spread over the predicted σ history, an ellipsoid at the
  planned position with half sizes σ_j / j_j × 0.5 m (a sphere of radius 0.5 m would be
  σ = 100 % of the nominal inertia). Only σ over time is known, not the full covariance
  over time, so these ignore correlations and are axis-aligned.
"""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from mavsysid.formats.rerun_file import atomic_recording
from mavsysid.planner.plan_result import PlanResult
from mavsysid.vehicle.config import PARAMETER_NAMES
from mavsysid.vehicle.rotation import matrix_to_quat

__all__ = ["APPLICATION_ID", "log_plan", "recording_id_for", "time_colors", "write_plan_rrd"]

APPLICATION_ID = "mavsysid"

# Fixed namespace so the same plan request always maps to the same recording id.
_NAMESPACE = uuid.UUID("5b0e8c2a-91f3-4c6d-8a7e-3d2f1b9c0e47")

#: Rate at which the planned flight is sampled for display, Hz.
PATH_RATE = 50.0
#: Display half size, m, of an inertia ellipsoid axis whose σ equals the nominal value.
ELLIPSOID_SCALE = 0.5
_ELLIPSOID_COUNT = 5
_INERTIA = slice(3, 6)

# Anchors of matplotlib's viridis (perceptually uniform, colour-blind safe), so that the
# time colouring needs no plotting library.
_VIRIDIS = np.array([(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98),
                     (253, 231, 37)], dtype=float)
_VERTEX_COLOR = (150, 150, 150)
_EDGE_COLOR = (150, 150, 150, 90)
_PATH_VERTEX_COLOR = (214, 39, 40)
_SERIES_COLORS = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40),
                  (148, 103, 189), (140, 86, 75))


def recording_id_for(result: PlanResult) -> str:
    """The recording id of a plan: a UUID derived from its kind, vehicle and settings."""
    return str(uuid.uuid5(_NAMESPACE,
                          f"plan:{result.kind}:{result.config.name}:{result.settings!r}"))


def time_colors(fraction: np.ndarray) -> np.ndarray:
    """RGB colours, shape (S, 3) uint8, for fractions of the flight in [0, 1], shape (S,)."""
    x = np.clip(np.asarray(fraction, dtype=float), 0.0, 1.0) * (len(_VIRIDIS) - 1)
    anchors = np.arange(len(_VIRIDIS))
    rgb = np.column_stack([np.interp(x, anchors, _VIRIDIS[:, c]) for c in range(3)])
    return np.round(rgb).astype(np.uint8)


def _log_graph(rec: rr.RecordingStream, result: PlanResult) -> None:
    """Vertices, feasible edges and the chosen vertices of the motion graph (static)."""
    graph = result.graph
    vertices = np.asarray(graph.vertices, dtype=float).reshape(-1, 4)
    if len(vertices):
        rec.log("planner/graph/vertices", rr.Points3D(vertices[:, :3], colors=[_VERTEX_COLOR],
                                                      radii=[0.02]), static=True, strict=True)
    if graph.edge_paths:
        strips = [np.asarray(p, dtype=float).reshape(-1, 3) for p in graph.edge_paths]
        rec.log("planner/graph/edges", rr.LineStrips3D(strips, colors=[_EDGE_COLOR],
                                                       radii=[0.003]), static=True, strict=True)
    if graph.path:
        rec.log("planner/graph/path", rr.Points3D(vertices[graph.path, :3],
                                                  colors=[_PATH_VERTEX_COLOR], radii=[0.04]),
                static=True, strict=True)


def _log_path(rec: rr.RecordingStream, result: PlanResult) -> None:
    """The planned flight coloured by time, and the moving reference point."""
    duration = result.trajectory.duration
    t = np.linspace(0.0, duration, max(2, int(np.ceil(duration * PATH_RATE)) + 1))
    position = result.trajectory.flat_outputs(t).position
    # A strip has one colour, so colouring by time takes one two-point strip per sample.
    strips = np.stack([position[:-1], position[1:]], axis=1)
    colors = time_colors(0.5 * (t[:-1] + t[1:]) / duration)
    rec.log("planner/path", rr.LineStrips3D(strips, colors=colors, radii=[0.01]), static=True,
            strict=True)
    rec.log("planner/vehicle", rr.Points3D.from_fields(colors=[_PATH_VERTEX_COLOR],
                                                       radii=[0.05]), static=True, strict=True)
    rec.send_columns("planner/vehicle", indexes=[rr.TimeColumn("time", duration=t)],
                     columns=rr.Points3D.columns(positions=position), strict=True)


def _log_sigma(rec: rr.RecordingStream, result: PlanResult) -> None:
    """Predicted σ per parameter over the flight, absolute (SI) and relative (%)."""
    t = np.asarray(result.sigma_times, dtype=float)
    if t.size == 0:
        return
    sigma = np.asarray(result.predicted_sigma, dtype=float).reshape(t.size, 6)
    nominal = np.abs(result.config.theta)
    for j, (name, color) in enumerate(zip(PARAMETER_NAMES, _SERIES_COLORS, strict=True)):
        for path, values, label in (
            (f"planner/sigma/{name}", sigma[:, j], f"σ {name}"),
            (f"planner/relative_sigma/{name}", 100.0 * sigma[:, j] / nominal[j],
             f"σ {name} / {name} (%)"),
        ):
            rec.log(path, rr.SeriesLines(colors=[color], names=[label]), static=True,
                    strict=True)
            rec.send_columns(path, indexes=[rr.TimeColumn("time", duration=t)],
                             columns=rr.Scalars.columns(scalars=values), strict=True)


def _log_inertia(rec: rr.RecordingStream, result: PlanResult) -> None:
    """The final inertia covariance ellipsoid (SI) and σ ellipsoids along the path."""
    block = np.asarray(result.predicted_covariance, dtype=float)[_INERTIA, _INERTIA]
    eigenvalues, vectors = np.linalg.eigh(0.5 * (block + block.T))
    if np.linalg.det(vectors) < 0.0:
        vectors[:, 0] = -vectors[:, 0]  # a rotation needs a right-handed basis
    xyzw = np.roll(matrix_to_quat(vectors), -1)  # [w, x, y, z] → rerun's [x, y, z, w]
    rec.log("planner/inertia_covariance",
            rr.Ellipsoids3D(half_sizes=[np.sqrt(np.clip(eigenvalues, 0.0, None))],
                            centers=[[0.0, 0.0, 0.0]], quaternions=[rr.Quaternion(xyzw=xyzw)],
                            colors=[_PATH_VERTEX_COLOR]),
            static=True, strict=True)
    t = np.asarray(result.sigma_times, dtype=float)
    if t.size == 0:
        return
    chosen = np.unique(np.round(np.linspace(0, t.size - 1, _ELLIPSOID_COUNT)).astype(int))
    sigma = np.asarray(result.predicted_sigma, dtype=float).reshape(t.size, 6)[chosen, _INERTIA]
    relative = sigma / np.abs(result.config.theta[_INERTIA])
    duration = result.trajectory.duration
    rec.log("planner/inertia_ellipsoids",
            rr.Ellipsoids3D(half_sizes=ELLIPSOID_SCALE * relative,
                            centers=result.trajectory.flat_outputs(t[chosen]).position,
                            colors=time_colors(t[chosen] / duration),
                            labels=[f"t = {v:.1f} s" for v in t[chosen]]),
            static=True, strict=True)


def _blueprint() -> rrb.Blueprint:
    """The 3-D plan beside the relative σ plot and the final inertia ellipsoid."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="planner", name="plan",
                              contents=["+ /planner/**", "- /planner/inertia_covariance"]),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="planner/relative_sigma", name="predicted σ (%)"),
                rrb.Spatial3DView(origin="planner/inertia_covariance",
                                  name="final inertia covariance (kg·m²)"),
            ),
        ),
        collapse_panels=True,
    )


def write_plan_rrd(path: str | Path, result: PlanResult) -> None:
    """Write a Rerun recording of a planned flight (see the module docstring for entities).

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file to write; its directory is created. It is replaced only once the
        recording is complete, so an interrupted write leaves any previous file intact.
    result : PlanResult
        The plan; its kind, vehicle and settings fix the recording id
        (`recording_id_for`).

    Notes
    -----
    As for the estimation recording, the data are reproducible but the file is not byte
    for byte: rerun 0.41 stamps chunks and rows with fresh random ids.
    """
    with atomic_recording(path, APPLICATION_ID, recording_id_for(result),
                          f"plan {result.kind} {result.config.name}", _blueprint()) as rec:
        log_plan(rec, result)


def log_plan(rec: rr.RecordingStream, result: PlanResult) -> None:
    """Log a plan's entities (module docstring) into an open recording, e.g. the demo's."""
    _log_graph(rec, result)
    _log_path(rec, result)
    _log_sigma(rec, result)
    _log_inertia(rec, result)
