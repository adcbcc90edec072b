"""The trajectory file (docs/architecture.md, "User-facing contract").

Sampled setpoints of a trajectory are `mavsysid.formats.setpoints_csv`.

A trajectory file is JSON::

    {"format": "mavsysid-trajectory", "format_version": 1,
     "kind": "dopt" | "random" | "excitation" | ...,
     "duration": T_total,                                   # s, sum of the segments
     "segments": [{"duration": T,                           # s
                   "position": [[x0, x1, …], [y…], [z…]],   # m, increasing powers of τ
                   "yaw": [ψ0, ψ1, …]}, …],                 # rad, increasing powers of τ
     "vehicle": {"name": str, "config_toml": str},         # the full config it was planned for
     "limits": {"rotor_speed_max": …, …},                  # every `Limits` field, SI
     "start": [x, y, z, yaw],                              # where the first segment starts
     "box": [x_min, y_min, z_min, x_max, y_max, z_max],    # m, or null
     "predicted_dopt": det(Σ_θ)^(1/6) (SI) or null,
     "predicted_covariance": 6×6 (SI) or null,
     "predicted_sigma": {"t": [...], "c_T": [...], …, "j_z": [...]} (s, SI) or null,
     "parameter_names": ["c_T", …, "j_z"],
     "planner": {seed, budget, planning_time, max_samples, …, samples, vertices, edges,
                 beliefs, elapsed, time_to_first_solution} or null,
     "software": {"name": "mavsysid", "version": str}}

τ is the local time of a segment, s (0 at its start). Position polynomials have N = 10
coefficients and yaw N = 6 for planned flights, but a reader accepts any N that is the
same for every segment. Required keys: ``format``, ``format_version``, ``kind``,
``duration``, ``segments``, ``vehicle``, ``limits`` (at least ``rotor_speed_max``) and
``start``; the others may be absent or null (an exported built-in excitation figure has no
box, prediction or planner). A planning time without limit is stored as null.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, fields
from importlib import metadata
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from mavsysid.formats.flight_dir import write_json_atomic
from mavsysid.formats.poselog import read_text_file
from mavsysid.vehicle.config import PARAMETER_NAMES, Limits, VehicleConfig, vehicle_to_toml
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import InputError

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "TrajectoryFile",
    "parse_trajectory",
    "read_trajectory",
    "trajectory_file_for",
    "write_trajectory_file",
]

FORMAT = "mavsysid-trajectory"
FORMAT_VERSION = 1

# JSON floats round-trip exactly, so a start that disagrees by more than rounding is a
# hand-edited or corrupted file, not noise.
_START_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class TrajectoryFile:
    """A trajectory file as read (see the module docstring for the format).

    Attributes
    ----------
    trajectory : PiecewisePolynomial
        The flight, world ENU.
    kind : str
        What made it: "dopt", "random", "excitation", …
    vehicle_name, vehicle_toml : str
        The vehicle it was made for: its name and its full configuration as TOML.
    limits : dict of str to float
        Limits it respects (every `Limits` field when written by mavsysid), SI.
    box : tuple of 6 float or None
        Flight volume [x_min, y_min, z_min, x_max, y_max, z_max], m.
    start : tuple of 4 float
        Start pose [x, y, z, yaw] (m, rad): the trajectory at t = 0.
    predicted_dopt : float or None
        Predicted D-optimality det(Σ_θ)^(1/6), SI.
    raw : dict
        The whole JSON document.
    """

    trajectory: PiecewisePolynomial
    kind: str
    vehicle_name: str
    vehicle_toml: str
    limits: dict[str, float]
    box: tuple[float, ...] | None
    start: tuple[float, float, float, float]
    predicted_dopt: float | None
    raw: dict[str, Any]

    def limits_config(self) -> Limits:
        """`limits` as a `Limits` (keys this version does not know are ignored)."""
        known = {f.name for f in fields(Limits)}
        return Limits(**{k: v for k, v in self.limits.items() if k in known})


# --- writing -----------------------------------------------------------------------------


def _software() -> dict[str, str]:
    try:
        return {"name": "mavsysid", "version": metadata.version("mavsysid")}
    except metadata.PackageNotFoundError:
        return {"name": "mavsysid", "version": "0+unknown"}


def trajectory_file_for(
    trajectory: PiecewisePolynomial, config: VehicleConfig, kind: str = "excitation",
    box: tuple[float, float, float, float, float, float] | None = None,
) -> dict[str, Any]:
    """The trajectory-file document of any polynomial trajectory, without a prediction.

    Parameters
    ----------
    trajectory : PiecewisePolynomial
        M segments, world ENU (the built-in excitation figure, say).
    config : VehicleConfig
        The vehicle it is meant for (its limits are stored with it).
    kind : str
        Stored as ``kind``.
    box : tuple of 6 float, optional
        Flight volume, m; null when not given.

    Returns
    -------
    dict
        JSON-ready; ``predicted_*`` and ``planner`` are None. Write it with
        `write_trajectory_file`.
    """
    start = trajectory.flat_outputs(np.array([0.0]))
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "duration": trajectory.duration,
        "segments": [
            {"duration": float(d), "position": p.tolist(), "yaw": y.tolist()}
            for d, p, y in zip(trajectory.durations, trajectory.position_coeffs,
                               trajectory.yaw_coeffs, strict=True)
        ],
        "vehicle": {"name": config.name, "config_toml": vehicle_to_toml(config)},
        "limits": {f.name: float(getattr(config.limits, f.name)) for f in fields(Limits)},
        "start": [*start.position[0].tolist(), float(start.yaw[0])],
        "box": None if box is None else [float(b) for b in box],
        "predicted_dopt": None,
        "predicted_covariance": None,
        "predicted_sigma": None,
        "parameter_names": list(PARAMETER_NAMES),
        "planner": None,
        "software": _software(),
    }


def write_trajectory_file(path: str | Path, document: Mapping[str, Any]) -> None:
    """Check `document` as `read_trajectory` would, then write it atomically.

    Parameters
    ----------
    path : str or Path
        The file to write.
    document : Mapping
        The trajectory document (schema in the module docstring).

    Raises
    ------
    InputError
        The document would not read back; nothing is written.
    """
    parse_trajectory(json.loads(json.dumps(dict(document), default=_plain)), str(path))
    write_json_atomic(path, document)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON")


# --- reading -----------------------------------------------------------------------------


_MISSING = object()


def _describe(value: Any) -> str:
    """A short one-line description of a JSON value for error messages."""
    if value is _MISSING:
        return "nothing (key missing)"
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, int) and abs(value) > 10**30:
        # repr of a huge int is slow, or refused beyond 4300 digits.
        return f"an integer of {len(format(abs(value), 'x')) * 4} bits"
    if isinstance(value, list | dict):
        return f"a list of {len(value)}" if isinstance(value, list) else "an object"
    return repr(value[:40] + "…" if isinstance(value, str) and len(value) > 40 else value)


def _fail(file: str, key: str, expected: str, value: Any) -> NoReturn:
    message = f"{file}: {key}: {expected}, got {_describe(value)}"
    raise InputError(" ".join(message.split()))


def _get(doc: Mapping[str, Any], key: str) -> Any:
    return doc.get(key, _MISSING)


def _number(file: str, key: str, value: Any, positive: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    try:
        number = float(value) if ok else math.nan  # an int beyond 1e308 overflows
    except OverflowError:
        number = math.nan
    if not math.isfinite(number) or (positive and number <= 0.0):
        _fail(file, key, "a positive number" if positive else "a finite number", value)
    return number


def _vector(file: str, key: str, value: Any, length: int | None = None) -> np.ndarray:
    if not isinstance(value, list) or (length is not None and len(value) != length):
        _fail(file, key, f"a list of {length} numbers" if length else "a list of numbers",
              value)
    return np.array([_number(file, f"{key}[{i}]", v) for i, v in enumerate(value)])


def _matrix(file: str, key: str, value: Any, rows: int, cols: int | None) -> np.ndarray:
    if not isinstance(value, list) or len(value) != rows:
        _fail(file, key, f"a list of {rows} rows", value)
    out = []
    for i, row in enumerate(value):
        out.append(_vector(file, f"{key}[{i}]", row, cols))
        cols = out[0].size  # later rows must match the first
    return np.array(out)


def _segments(file: str, value: Any) -> PiecewisePolynomial:
    if not isinstance(value, list) or not value:
        _fail(file, "segments", "a non-empty list of segments", value)
    durations, position, yaw = [], [], []
    for i, segment in enumerate(value):
        key = f"segments[{i}]"
        if not isinstance(segment, dict):
            _fail(file, key, "an object with duration, position and yaw", segment)
        durations.append(_number(file, f"{key}.duration", _get(segment, "duration"), True))
        # Every segment must have the first segment's polynomial orders.
        n, ny = (position[0].shape[1], yaw[0].size) if position else (None, None)
        position.append(_matrix(file, f"{key}.position", _get(segment, "position"), 3, n))
        yaw.append(_vector(file, f"{key}.yaw", _get(segment, "yaw"), ny))
        if position[0].shape[1] == 0 or yaw[0].size == 0:
            _fail(file, key, "position and yaw with at least one coefficient", [])
    return PiecewisePolynomial(np.array(durations), np.array(position), np.array(yaw))


def _optional_blocks(file: str, doc: Mapping[str, Any]) -> float | None:
    """Check the optional prediction and planner blocks; return the predicted D-opt."""
    given = {k for k, v in doc.items() if v is not None}
    if "predicted_covariance" in given:
        _matrix(file, "predicted_covariance", doc["predicted_covariance"], 6, 6)
    for key in ("predicted_sigma", "planner", "software"):
        if key in given and not isinstance(doc[key], dict):
            _fail(file, key, "an object or null", doc[key])
    if "predicted_sigma" in given:
        n = len(_vector(file, "predicted_sigma.t", _get(doc["predicted_sigma"], "t")))
        for name in PARAMETER_NAMES:
            _vector(file, f"predicted_sigma.{name}", _get(doc["predicted_sigma"], name), n)
    if "predicted_dopt" not in given:
        return None
    return _number(file, "predicted_dopt", doc["predicted_dopt"], positive=True)


def parse_trajectory(document: Any, source: str) -> TrajectoryFile:
    """Check a parsed trajectory-file document and build the `TrajectoryFile`.

    Parameters
    ----------
    document : Any
        The parsed JSON.
    source : str
        How to name the file in error messages.

    Raises
    ------
    InputError
        One line naming `source`, the offending key and what was expected.
    """
    if not isinstance(document, dict):
        _fail(source, "document", "a JSON object", document)
    doc: dict[str, Any] = document
    if _get(doc, "format") != FORMAT:
        _fail(source, "format", f'"{FORMAT}" (a mavsysid trajectory file)', _get(doc, "format"))
    version = _get(doc, "format_version")
    if version != FORMAT_VERSION or isinstance(version, bool):
        _fail(source, "format_version", f"{FORMAT_VERSION} (the version this mavsysid reads)",
              version)
    kind = _get(doc, "kind")
    if not isinstance(kind, str) or not kind:
        _fail(source, "kind", "a non-empty string", kind)
    trajectory = _segments(source, _get(doc, "segments"))
    duration = _number(source, "duration", _get(doc, "duration"), True)
    with np.errstate(over="ignore"):  # durations near 1e308 sum to inf: refused below
        total = float(np.sum(trajectory.durations))
    if not math.isclose(duration, total, rel_tol=1e-9, abs_tol=1e-9):
        _fail(source, "duration", f"the sum of the segment durations ({total!r} s)",
              duration)
    vehicle = _get(doc, "vehicle")
    if not isinstance(vehicle, dict):
        _fail(source, "vehicle", "an object with name and config_toml", vehicle)
    name, toml_text = _get(vehicle, "name"), _get(vehicle, "config_toml")
    if not isinstance(name, str) or not name:
        _fail(source, "vehicle.name", "a non-empty string", name)
    if not isinstance(toml_text, str):
        _fail(source, "vehicle.config_toml", "the vehicle configuration as TOML text", toml_text)
    try:
        tomllib.loads(toml_text)
    except tomllib.TOMLDecodeError as error:
        _fail(source, "vehicle.config_toml", "valid TOML", f"{error}")
    limits = _get(doc, "limits")
    if not isinstance(limits, dict) or "rotor_speed_max" not in limits:
        _fail(source, "limits", "an object with at least rotor_speed_max", limits)
    limits = {k: _number(source, f"limits.{k}", v) for k, v in limits.items()}
    box: tuple[float, ...] | None = None
    if _get(doc, "box") not in (None, _MISSING):
        corners = _vector(source, "box", doc["box"], 6)
        if np.any(corners[:3] >= corners[3:]):
            _fail(source, "box", "[x_min, y_min, z_min, x_max, y_max, z_max] with min < max",
                  corners.tolist())
        box = tuple(corners.tolist())
    start = _vector(source, "start", _get(doc, "start"), 4)
    # The constant terms: the flight at t = 0 (evaluating more could overflow).
    at_zero = np.array([*trajectory.position_coeffs[0, :, 0], trajectory.yaw_coeffs[0, 0]])
    if np.max(np.abs(start - at_zero)) > _START_TOLERANCE:
        _fail(source, "start", f"the first segment's start {at_zero.tolist()}", start.tolist())
    return TrajectoryFile(
        trajectory=trajectory, kind=kind, vehicle_name=name, vehicle_toml=toml_text,
        limits=limits, box=box,
        start=(float(start[0]), float(start[1]), float(start[2]), float(start[3])),
        predicted_dopt=_optional_blocks(source, doc), raw=doc,
    )


def read_trajectory(path: str | Path) -> TrajectoryFile:
    """Read and check a trajectory file.

    Parameters
    ----------
    path : str or Path
        The trajectory file (``.json``).

    Raises
    ------
    InputError
        An unreadable file, invalid JSON, an unknown format or version, or a missing,
        malformed or non-finite value; one line naming the file and the key.
    """
    path = Path(path)
    text = read_text_file(path)
    try:
        # JSON has no NaN or infinity, but Python writes them: read them as floats so
        # that the checks name the key that holds them.
        document = json.loads(text, parse_constant=float)
    except json.JSONDecodeError as error:
        raise InputError(f"{path}: line {error.lineno}, column {error.colno}: not valid "
                         f"JSON: {error.msg}") from None
    except (ValueError, RecursionError) as error:
        # An integer of more than 4300 digits, or arrays nested thousands deep.
        what = "nested too deeply" if isinstance(error, RecursionError) else str(error)
        raise InputError(f"{path}: not a usable JSON document: {what}") from None
    try:
        return parse_trajectory(document, str(path))
    except RecursionError:
        raise InputError(f"{path}: not a usable JSON document: nested too deeply") from None
