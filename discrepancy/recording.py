"""A Rerun recording of a diagnosis (``mavsysid diagnose --rrd FILE``).

Entities (time series on the ``time`` timeline, s from the start of the log):

- ``residual/<axis>/before`` and ``/after``: the residual of the base and the augmented
  model per axis (`mavsysid.discrepancy.residuals.AXIS_NAMES`; m/s² and rad/s²), whole flight;
  ``residual/heldout_start`` marks where the held-out part begins (static text).
- ``candidates/step<k>/<name>``: ΔBIC of every candidate at selection step k (a bar
  chart, static).
- ``world/trajectory``: the smoothed path coloured by the base model's normalised
  residual (blue small → red large), static; ``world/residual_norm`` the same as a series.
- ``rotors/n<i>`` (i = 1 … k, the config's rotor order): the logged rotor speeds, rad/s,
  when the flight is given.
"""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from mavsysid.discrepancy.diagnosis import Diagnosis
from mavsysid.discrepancy.residuals import AXIS_NAMES
from mavsysid.estimation import (
    ROTOR_COLORS,
    FlightData,
)
from mavsysid.formats.rerun_file import atomic_recording

__all__ = ["log_diagnosis", "recording_id_for", "write_diagnosis_rrd"]

_NAMESPACE = uuid.UUID("5b1e0c7a-2f3d-4e8b-9a6c-1d2e3f4a5b6c")
_BEFORE = (214, 39, 40)
_AFTER = (31, 119, 180)


def recording_id_for(log_name: str) -> str:
    """The recording id of a diagnosis of ``log_name`` (a UUID derived from the name)."""
    return str(uuid.uuid5(_NAMESPACE, f"diagnose:{log_name}"))


def _series(rec: rr.RecordingStream, path: str, t: np.ndarray, values: np.ndarray,
            name: str, color: tuple[int, int, int]) -> None:
    rec.log(path, rr.SeriesLines(colors=[color], names=[name]), static=True, strict=True)
    rec.send_columns(path, indexes=[rr.TimeColumn("time", duration=t)],
                     columns=rr.Scalars.columns(scalars=np.asarray(values, float)), strict=True)


def _colours(z: np.ndarray) -> np.ndarray:
    """Blue (≤ 1× noise) to red (≥ 4× noise), (N, 3) uint8."""
    s = np.clip((z - 1.0) / 3.0, 0.0, 1.0)[:, None]
    return (np.array(_AFTER) * (1.0 - s) + np.array(_BEFORE) * s).astype(np.uint8)


def write_diagnosis_rrd(path: str | Path, diagnosis: Diagnosis, log_name: str,
                        flight: FlightData | None = None) -> None:
    """Write a Rerun recording of ``diagnosis`` (entities: module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file; replaced only once complete.
    diagnosis : Diagnosis
    log_name : str
        Names the recording and fixes its id.
    flight : FlightData, optional
        The flight diagnosed: its rotor speeds are logged too.
    """
    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.Grid(*[rrb.TimeSeriesView(origin=f"residual/{a}", name=a) for a in AXIS_NAMES],
                 grid_columns=2, name="residuals"),
        rrb.Vertical(rrb.Spatial3DView(origin="world", name="trajectory by residual"),
                     rrb.BarChartView(origin="candidates", name="candidate ΔBIC"),
                     rrb.TimeSeriesView(origin="rotors", name="rotor speeds")),
    ), collapse_panels=True)
    with atomic_recording(path, "mavsysid", recording_id_for(log_name),
                          f"diagnose {log_name}", blueprint) as rec:
        log_diagnosis(rec, diagnosis, flight)


def log_diagnosis(rec: rr.RecordingStream, diagnosis: Diagnosis,
                  flight: FlightData | None = None) -> None:
    """Log a diagnosis's entities (module docstring) into an open recording, e.g. the demo's."""
    d = diagnosis
    used = d.used
    t = d.t[used]
    for a, axis in enumerate(AXIS_NAMES):
        _series(rec, f"residual/{axis}/before", t, d.residual_before[used, a],
                f"{axis} before", _BEFORE)
        _series(rec, f"residual/{axis}/after", t, d.residual_after[used, a],
                f"{axis} after", _AFTER)
    rec.log("residual/heldout_start",
            rr.TextDocument(f"held-out data from t = {d.split_time:.2f} s"), static=True,
            strict=True)
    steps = sorted({s.step for s in d.scores})
    for step in steps:
        scores = [s for s in d.scores if s.step == step]
        rec.log(f"candidates/step{step}",
                rr.BarChart(np.array([s.delta_bic for s in scores])), static=True,
                strict=True)
        rec.log(f"candidates/step{step}/names",
                rr.TextDocument(", ".join(s.name for s in scores)), static=True, strict=True)
    z = np.sqrt(np.mean((d.residual_before[used] / d.where.noise) ** 2, axis=1))
    position = d.pose.position[used]
    rec.log("world/trajectory", rr.Points3D(position, colors=_colours(z), radii=0.01),
            static=True, strict=True)
    _series(rec, "world/residual_norm", t, z, "residual / noise", _BEFORE)
    if flight is not None:
        speeds = np.asarray(flight.rotor_speeds, float)
        for i in range(speeds.shape[1]):
            _series(rec, f"rotors/n{i + 1}", flight.t, speeds[:, i], f"n{i + 1} (rad/s)",
                    ROTOR_COLORS[i % len(ROTOR_COLORS)])
