"""A Rerun recording of an estimation run (``mavsysid estimate --rrd FILE``).

Entities (time series on the ``time`` timeline, s from the start of the log):
``parameters/<name>/estimate``, ``/upper``, ``/lower`` (the filter's θ_j and θ_j ± σ_j, SI;
``/true`` when the truth is known, ``/refined`` when refinement ran); ``world/measured`` and
``world/filtered`` (the position, m, world ENU); ``innovations/position/{x,y,z}``,
``innovations/attitude/{x,y,z}``, ``innovations/nis`` with its χ²(6) bound; ``rotors/n<i>``
(the logged rotor speeds, rad/s); and the answer as a markdown panel.
"""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import EstimationResult
from mavsysid.formats.rerun_file import atomic_recording
from mavsysid.vehicle.config import PARAMETER_NAMES
from scipy.stats import chi2

__all__ = ["APPLICATION_ID", "ROTOR_COLORS", "answer_markdown", "log_estimation",
           "recording_id_for", "write_estimation_rrd"]


APPLICATION_ID = "mavsysid"

# Fixed namespace so a log name always maps to the same recording id, on any machine.
_NAMESPACE = uuid.UUID("0f6a3c52-4d0e-5b8e-9c1a-7e2d4b6f8a10")

_ESTIMATE_COLOR = (31, 119, 180)
_BAND_COLOR = (31, 119, 180, 110)
_TRUE_COLOR = (44, 160, 44)
_REFINED_COLOR = (214, 39, 40)
_AXIS_COLORS = ((230, 60, 60), (60, 180, 60), (60, 90, 230))
_MEASURED_COLOR = (255, 140, 0)
_FILTERED_COLOR = (31, 119, 180)
#: Colours of the rotor-speed series (matplotlib's tab10, so they look as in the report's
#: PNG), RGB; rotor i takes entry i mod 8.
ROTOR_COLORS: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40),
    (148, 103, 189), (140, 86, 75), (227, 119, 194), (127, 127, 127))


def recording_id_for(log_name: str) -> str:
    """The recording id of an estimation of `log_name` (a UUID derived from the name)."""
    return str(uuid.uuid5(_NAMESPACE, f"estimate:{log_name}"))


def _series(rec: rr.RecordingStream, path: str, t: np.ndarray, values: np.ndarray,
            name: str, color: tuple[int, ...], width: float = 1.5) -> None:
    """One scalar time series with its line style (the style is static)."""
    rec.log(path, rr.SeriesLines(colors=[color], names=[name], widths=[width]), static=True,
            strict=True)
    rec.send_columns(path, indexes=[rr.TimeColumn("time", duration=t)],
                     columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)),
                     strict=True)


def _log_parameters(rec: rr.RecordingStream, result: EstimationResult) -> None:
    """Filter estimate with ±σ band per parameter, plus truth and refined lines."""
    history = result.history
    t = history.t
    for j, name in enumerate(PARAMETER_NAMES):
        base = f"parameters/{name}"
        theta, sigma = history.theta[:, j], history.theta_sigma[:, j]
        _series(rec, f"{base}/estimate", t, theta, f"{name} filter", _ESTIMATE_COLOR, 2.0)
        _series(rec, f"{base}/upper", t, theta + sigma, f"{name} + σ", _BAND_COLOR, 1.0)
        _series(rec, f"{base}/lower", t, theta - sigma, f"{name} − σ", _BAND_COLOR, 1.0)
        # Constant lines are sampled at every step so they span exactly the filter's run.
        if result.true_theta is not None:
            _series(rec, f"{base}/true", t, np.full(t.shape, result.true_theta[j]),
                    f"{name} true", _TRUE_COLOR)
        if result.refined is not None:
            _series(rec, f"{base}/refined", t, np.full(t.shape, result.refined.value[j]),
                    f"{name} refined", _REFINED_COLOR)


def answer_markdown(result: EstimationResult) -> str:
    """The final θ per parameter (value, σ, status, source) and the held-out check, Markdown.

    Parameters
    ----------
    result : EstimationResult
        The estimate, with its per-parameter answer.
    """
    final = result.final
    lines = ["| parameter | value | σ | status | from |", "|---|---|---|---|---|"]
    for j, name in enumerate(PARAMETER_NAMES):
        status = result.status[j] if result.status else "determined"
        source = result.answer_source[j] if result.answer_source else "filter"
        lines.append(f"| {name} | {final.value[j]:.4g} | {final.sigma[j]:.2g} | {status} | "
                     f"{source} |")
    holdout = None if result.balance is None else result.balance.holdout
    if holdout is not None:
        lines += ["", f"Held-out check (fitted before t = {holdout.start:.2f} s): force RMSE "
                  f"ratio to the prior model {holdout.force_ratio:.3g}, angular acceleration "
                  f"{holdout.torque_ratio:.3g} (below 1: better than the prior)."]
    if result.mismatch:
        lines += ["", "Filter and balance disagree (the balance stands): "
                  + "; ".join(result.mismatch)]
    return "\n".join(lines)


def _log_answer(rec: rr.RecordingStream, result: EstimationResult) -> None:
    """The answer as a static text document, and the held-out RMSE ratios as scalars."""
    rec.log("estimate/answer", rr.TextDocument(answer_markdown(result),
                                               media_type=rr.MediaType.MARKDOWN), static=True)
    holdout = None if result.balance is None else result.balance.holdout
    if holdout is not None:
        for name, ratio in (("force", holdout.force_ratio), ("torque", holdout.torque_ratio)):
            if np.isfinite(ratio):
                rec.log(f"estimate/holdout_ratio/{name}", rr.Scalars([float(ratio)]),
                        static=True)


def _log_trajectories(rec: rr.RecordingStream, result: EstimationResult,
                      flight: FlightData) -> None:
    """Measured and filtered positions, as moving points and as whole paths."""
    for label, t, position, color in (
        ("measured", flight.t, flight.position, _MEASURED_COLOR),
        ("filtered", result.history.t, result.history.position, _FILTERED_COLOR),
    ):
        position = np.asarray(position, dtype=float)
        rec.log(f"world/{label}_path", rr.LineStrips3D([position], colors=[color],
                                                       radii=[0.002]), static=True, strict=True)
        rec.log(f"world/{label}", rr.Points3D.from_fields(colors=[color], radii=[0.02]),
                static=True, strict=True)
        rec.send_columns(f"world/{label}", indexes=[rr.TimeColumn("time", duration=t)],
                         columns=rr.Points3D.columns(positions=position), strict=True)


def _log_innovations(rec: rr.RecordingStream, result: EstimationResult) -> None:
    """Innovation per axis and NIS with its 95 % consistency bound."""
    history = result.history
    t = history.t
    for block, (kind, unit) in enumerate((("position", "m"), ("attitude", "rad"))):
        for axis, (letter, color) in enumerate(zip("xyz", _AXIS_COLORS, strict=True)):
            _series(rec, f"innovations/{kind}/{letter}", t,
                    history.innovation[:, 3 * block + axis], f"{kind} {letter} ({unit})",
                    color)
    _series(rec, "innovations/nis", t, history.nis, "NIS", _ESTIMATE_COLOR)
    # NIS of a consistent filter is χ² with 6 degrees of freedom (3 position + 3 attitude).
    bound = float(chi2.ppf(0.95, df=6))
    _series(rec, "innovations/nis_bound", t, np.full(t.shape, bound), "χ²(6) 95 %",
            _REFINED_COLOR, 1.0)


def _log_rotor_speeds(rec: rr.RecordingStream, flight: FlightData) -> None:
    """The logged rotor speeds, one series per rotor."""
    speeds = np.asarray(flight.rotor_speeds, dtype=float)
    for i in range(speeds.shape[1]):
        _series(rec, f"rotors/n{i + 1}", flight.t, speeds[:, i], f"n{i + 1} (rad/s)",
                ROTOR_COLORS[i % len(ROTOR_COLORS)])


def _blueprint() -> rrb.Blueprint:
    """One plot per parameter, the 3-D trajectories and the innovation plots."""
    parameter_views = [rrb.TimeSeriesView(origin=f"parameters/{name}", name=name)
                       for name in PARAMETER_NAMES]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*parameter_views, grid_columns=2, name="parameters"),
            rrb.Vertical(
                rrb.Spatial3DView(origin="world", name="trajectory"),
                rrb.TimeSeriesView(origin="innovations/position", name="position innovation"),
                rrb.TimeSeriesView(origin="innovations/attitude", name="attitude innovation"),
                rrb.TimeSeriesView(origin="innovations", name="NIS",
                                   contents=["innovations/nis", "innovations/nis_bound"]),
                rrb.TimeSeriesView(origin="rotors", name="rotor speeds"),
            ),
        ),
        collapse_panels=True,
    )


def write_estimation_rrd(path: str | Path, result: EstimationResult, flight: FlightData) -> None:
    """Write a Rerun recording of an estimation run (see the module docstring for entities).

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file to write; its directory is created. It is replaced only once the
        recording is complete, so an interrupted write leaves any previous file intact.
    result : EstimationResult
        The estimate and its history (N filter steps).
    flight : FlightData
        The flight it was estimated from (M pose samples; `flight.source` names the log
        and fixes the recording id, see `recording_id_for`).

    Notes
    -----
    The recording id is derived from the log name, so every estimate of one log has the
    same id (a viewer that opens two such files merges them into one recording, as rerun
    does for any shared id). The file is not byte-for-byte
    reproducible: rerun 0.41 stamps every chunk and row with fresh time-based random ids
    (TUIDs), and exposes no way to seed them.
    """
    with atomic_recording(path, APPLICATION_ID, recording_id_for(flight.source),
                          f"estimate {flight.source}", _blueprint()) as rec:
        log_estimation(rec, result, flight)


def log_estimation(rec: rr.RecordingStream, result: EstimationResult,
                   flight: FlightData) -> None:
    """Log an estimate's entities (module docstring) into an open recording, e.g. the demo's."""
    _log_parameters(rec, result)
    _log_answer(rec, result)
    _log_trajectories(rec, result, flight)
    _log_innovations(rec, result)
    _log_rotor_speeds(rec, flight)
