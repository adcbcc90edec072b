"""What `estimate` tells the user in words and numbers: a table on stdout, ``estimate.json``,
the updated vehicle config and the estimate over time as CSV.

The JSON follows docs/architecture.md's user-facing contract (``{"parameters": {"c_T":
{"value", "sigma", ...}, ...}, ...}``, nuisance quantities beyond θ under ``"nuisance"``);
everything in it is SI, and quantities that do not exist (a parameter that never
converged, no refinement) are ``null``, never NaN. The history CSV (``--history``) has one
row per filter step: ``t`` (s, the log's clock), each parameter's filtered value and σ,
then the NIS, with 17 significant digits so that reading it back gives the filter's
numbers exactly.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
from collections import Counter
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from mavsysid.estimation.results import (
    CONVERGENCE_TOLERANCE,
    DETERMINED,
    MAX_RELATIVE_SIGMA,
    EstimationHistory,
    EstimationResult,
    NoiseMet,
    ParameterEstimate,
)
from mavsysid.formats.flight_dir import write_json_atomic
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, VehicleConfig

from mavsysid.errors import InputError

__all__ = ["HISTORY_COLUMNS", "format_table", "history_frame", "noise_from_flights",
           "read_noise_met", "read_set_aside", "result_to_json", "software_version",
           "updated_vehicle", "write_estimate_json", "write_history_csv"]


_POSE_SOURCE_LABELS = {"motion_capture": "motion capture", "autopilot": "autopilot"}


def software_version() -> str:
    """The installed mavsysid version, ``"0+unknown"`` when run from an uninstalled tree."""
    try:
        return importlib.metadata.version("mavsysid")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"


# --- the table on stdout ---------------------------------------------------------------


def _fmt(value: float, spec: str, missing: str = "n/a") -> str:
    """`value` formatted with `spec`, or `missing` when it is NaN or infinite."""
    return format(value, spec) if math.isfinite(value) else missing


def _relative(difference: float, reference: float) -> float:
    """difference / |reference|, NaN when the reference is 0 (a simulated c_D = 0, say)."""
    return difference / abs(reference) if reference != 0.0 else math.nan


def _percent(fraction: float) -> str:
    """A relative quantity as a percentage with two decimals, "<0.01" below that."""
    percent = 100.0 * fraction
    # Two decimals read well in a column; tiny values must not print as a bare 0.00.
    return "<0.01" if 0.0 <= percent < 0.005 else _fmt(percent, ".2f")


def _rows(header: list[str], rows: list[list[str]], left: int = 1) -> list[str]:
    """Fixed-width lines: the first `left` columns left-aligned, the rest right-aligned."""
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]

    def line(cells: list[str]) -> str:
        parts = [c.ljust(w) if i < left else c.rjust(w)
                 for i, (c, w) in enumerate(zip(cells, widths, strict=True))]
        return "  ".join(parts).rstrip()

    return [line(header), *(line(r) for r in rows)]


def _header(result: EstimationResult, config: VehicleConfig, log_name: str) -> list[str]:
    """Where the numbers come from: log, vehicle, pose source and assumed noise."""
    position_sigma, attitude_sigma = result.measurement_sigma
    source = _POSE_SOURCE_LABELS.get(result.pose_source, result.pose_source)
    lines = [
        f"Parameter estimate from {log_name}",
        f"  vehicle      {config.name} (mass {config.mass:.4g} kg, {config.rotor_count} rotors)",
        f"  pose source  {source}; measurement σ assumed {position_sigma * 1e3:.2f} mm, "
        f"{math.degrees(attitude_sigma):.3f}°",
    ]
    if result.pose_source == "autopilot":
        lines += [
            "               The pose comes from the autopilot's own estimator (filtered and",
            "               lagged), so a larger measurement noise was assumed and the",
            "               results are less certain than with motion capture.",
        ]
    return lines


def _main_block(result: EstimationResult) -> list[str]:
    """One row per parameter: prior, final estimate, σ, convergence (and truth)."""
    final = result.final
    truth = result.true_theta
    header = ["parameter", "unit", "prior", "estimate", "σ", "σ/|θ| %", "converged s"]
    if truth is not None:
        header += ["true", "error %"]
    if result.status:
        header += ["status", "from"]
    rows = []
    for j, name in enumerate(PARAMETER_NAMES):
        value = float(final.value[j])
        row = [
            name,
            PARAMETER_UNITS[name],
            _fmt(float(result.prior.value[j]), ".3e"),
            _fmt(value, ".3e"),
            _fmt(float(final.sigma[j]), ".2e"),
            _percent(_relative(float(final.sigma[j]), value)),
            _fmt(float(result.convergence_time[j]), ".2f", missing="—"),
        ]
        if truth is not None:
            true_value = float(truth[j])
            row += [_fmt(true_value, ".3e"),
                    _fmt(100.0 * _relative(value - true_value, true_value), "+.2f")]
        if result.status:
            row += [result.status[j], result.answer_source[j]]
        rows.append(row)
    which = "batch refinement" if result.refined is not None else "filter"
    if result.status:
        which = ("per parameter (from: the filter and batch refinement, the force and "
                 "torque balance, or the prior)")
    target = "the truth" if truth is not None else "its own final value"
    return [
        *_rows(header, rows, left=2),
        f"estimate: {which}; σ: its standard deviation; converged: first time after which",
        f"the filter estimate stays within {100 * CONVERGENCE_TOLERANCE:g} % of {target} "
        "(— never).",
    ]


def _effects_block(result: EstimationResult) -> list[str]:
    """One row per effect parameter: value, σ and 95 % interval (or "given")."""
    header = ["effect", "parameter", "unit", "value", "σ", "95 % interval"]
    rows = []
    for fe in result.effects:
        lo, hi = fe.ci95
        for j, p in enumerate(fe.effect.parameters):
            interval = (f"[{_fmt(float(lo[j]), '.4g')}, {_fmt(float(hi[j]), '.4g')}]"
                        if fe.fitted else "given")
            rows.append([fe.name, p.name, p.unit, _fmt(float(fe.value[j]), ".4g"),
                         _fmt(float(fe.sigma[j]), ".2g", missing="—"), interval])
    return ["Model effects", *_rows(header, rows, left=3)]


def _refined_block(filtered: ParameterEstimate, refined: ParameterEstimate) -> list[str]:
    """Filter and refined estimates side by side, value and σ."""
    header = ["parameter", "filter", "σ", "refined", "σ"]
    rows = [[name, _fmt(float(filtered.value[j]), ".3e"), _fmt(float(filtered.sigma[j]), ".2e"),
             _fmt(float(refined.value[j]), ".3e"), _fmt(float(refined.sigma[j]), ".2e")]
            for j, name in enumerate(PARAMETER_NAMES)]
    return ["Filter vs batch refinement", *_rows(header, rows)]


def _pooled(rmse: np.ndarray) -> float:
    """RMSE pooled over the axes that have one; NaN if none."""
    live = rmse[np.isfinite(rmse)]
    return float(np.sqrt(np.mean(live**2))) if live.size else float("nan")


def _balance_block(balance: Any) -> list[str]:
    """The force and torque balance: its choices and the held-out check."""
    c = balance.choices
    band = ("none" if c.roll_pitch is None
            else f"{c.roll_pitch.low:.3g}–{c.roll_pitch.high:.3g} Hz")
    lines = ["Force and torque balance",
             f"  smoothing window {1000 * c.window:.0f} ms; roll/pitch band {band}; "
             f"pose lags the rotor speeds by {1000 * c.delay:+.1f} ± "
             f"{_fmt(1000 * balance.delay_sigma, '.1f')} ms"]
    h = balance.holdout
    if h is None:
        lines.append("  held-out check: none (the flight is too short to hold a part out)")
        return lines
    lines += [
        f"  held-out check (fitted before t = {h.start:.2f} s, predicting the rest, "
        f"{h.rows} rows):",
        f"    force RMSE {_fmt(_pooled(h.rmse[:3]), '.3g')} m/s², "
        f"{_fmt(h.force_ratio, '.2f')} × the prior model's; angular acceleration RMSE "
        f"{_fmt(_pooled(h.rmse[3:]), '.3g')} rad/s², {_fmt(h.torque_ratio, '.2f')} × the "
        "prior model's",
        "    (below 1: the estimate predicts unseen data better than the prior)"]
    return lines


def format_table(result: EstimationResult, config: VehicleConfig, log_name: str) -> str:
    """The human-readable report printed by ``mavsysid estimate``.

    Parameters
    ----------
    result : EstimationResult
        The estimate to report.
    config : VehicleConfig
        The vehicle it was estimated for (name, mass).
    log_name : str
        How to name the log (usually its path as given by the user).

    Returns
    -------
    str
        Fixed-width text ending in a newline: header lines, one row per parameter,
        the model effects with their parameters when there are any, the filter-vs-refined
        comparison when the result was refined, the result's notes
        and a reminder that mass and rotor geometry are taken as known.
    """
    lines = [*_header(result, config, log_name), "", *_main_block(result)]
    if result.effects:
        lines += ["", *_effects_block(result)]
    if result.refined is not None:
        lines += ["", *_refined_block(result.filtered, result.refined)]
    if result.balance is not None:
        lines += ["", *_balance_block(result.balance)]
    lines.append("")
    lines += [f"note: {note}" for note in result.notes]
    lines += [
        f"Mass ({config.mass:.4g} kg) and rotor geometry are taken as known: a wrong mass "
        "scales c_T, c_M and J",
        "together and cannot be detected from pose and rotor speeds.",
    ]
    return "\n".join(lines) + "\n"


# --- estimate.json ---------------------------------------------------------------------


def _number(value: float) -> float | None:
    """A JSON number, or None for NaN and infinity (JSON has neither)."""
    value = float(value)
    return value if math.isfinite(value) else None


def _block(
    estimate: ParameterEstimate, convergence: np.ndarray | None, truth: np.ndarray | None
) -> dict[str, dict[str, float | str | None]]:
    """One estimate as ``{name: {"value", "unit", "sigma", "relative_sigma", ...}}``."""
    out: dict[str, dict[str, float | str | None]] = {}
    for j, name in enumerate(PARAMETER_NAMES):
        value, sigma = float(estimate.value[j]), float(estimate.sigma[j])
        entry: dict[str, float | str | None] = {
            "value": _number(value),
            "unit": PARAMETER_UNITS[name],
            "sigma": _number(sigma),
            "relative_sigma": _number(_relative(sigma, value)),
            "convergence_time_s": None if convergence is None else _number(convergence[j]),
        }
        if truth is not None:
            true_value = float(truth[j])
            entry["true_value"] = _number(true_value)
            entry["error_relative"] = _number(_relative(value - true_value, true_value))
        out[name] = entry
    return out


def _nuisance_block(result: EstimationResult, config: VehicleConfig
                    ) -> dict[str, dict[str, Any]]:
    """The answer's nuisance quantities: ``{name: {"value", "unit", "sigma", "status",
    "source", "prior_value", "prior_sigma"}}`` (empty for the paper's θ alone)."""
    final, prior = result.final, result.prior
    six = len(PARAMETER_NAMES)
    units = {q.name: q.unit for q in config.extra_quantities}
    out: dict[str, dict[str, Any]] = {}
    for j, name in enumerate(final.names[six:], start=six):
        out[name] = {"value": _number(final.value[j]), "unit": units.get(name),
                     "sigma": _number(final.sigma[j]),
                     "status": result.status[j] if result.status else None,
                     "source": result.answer_source[j] if result.status else None,
                     "prior_value": _number(prior.value[j]),
                     "prior_sigma": _number(prior.sigma[j])}
    return out


def result_to_json(
    result: EstimationResult, config: VehicleConfig, log_path: str | Path
) -> dict[str, Any]:
    """The ``estimate.json`` document (docs/architecture.md, "User-facing contract").

    Parameters
    ----------
    result : EstimationResult
        The estimate to write.
    config : VehicleConfig
        The vehicle it was estimated for.
    log_path : str or Path
        The log it was estimated from, stored as given.

    Returns
    -------
    dict
        JSON-ready (no NaN; absent quantities are None). Keys: ``effects``, a list of
        ``{"name", "fitted", "parameters": {p: {"value", "sigma", "ci95", "unit"}}}`` in
        the model's order (σ and ``ci95`` None for values given, not fitted; empty for the
        paper's model), ``log_likelihood`` (the filter's innovation log-likelihood, see
        `EstimationResult.log_likelihood`), ``parameters`` (the final
        estimate: refined if present, else the filter's), ``filter``, ``refined`` (or
        None) and ``prior``, each ``{name: {"value", "unit", "sigma", "relative_sigma",
        "convergence_time_s"}}`` (``unit`` from `PARAMETER_UNITS`, the unit of value and
        σ) plus ``"true_value"`` and ``"error_relative"`` (signed,
        (value − true)/|true|) when the truth is known. ``convergence_time_s`` (s) is the
        filter's (see `EstimationResult.convergence_time`): given in ``parameters`` and
        ``filter``, None there for a parameter that never settled, and always None in
        ``refined`` and ``prior``, which have no time history. Also ``covariance`` (final, SI,
        in the order of ``parameter_names``: θ, then any nuisance quantities, which
        ``nuisance`` holds as `_nuisance_block` says),
        ``parameter_names``, ``log``, ``vehicle``, ``pose_source``,
        ``measurement_sigma`` (``position_m``, ``attitude_rad``), ``noise_met`` (what the
        filter met: ``position_m``, ``attitude_rad``, ``pose_rate_hz``,
        ``force_density``, ``moment_density``; None where no filter ran: what ``plan
        --noise-from`` reads), ``notes`` and ``software`` (``name``, ``version``). With
        the per-parameter answer (`mavsysid.estimation.answer`), each entry of ``parameters`` adds
        ``status`` ("determined", "not determined by this flight", "at the bound") and
        ``source`` ("filter", "balance", "prior"); ``balance`` is the force and torque
        balance (`WrenchBalanceResult.as_dict`) or None, ``holdout`` its held-out check
        (RMSE per axis and ratios to the prior model) or None, ``mismatch`` the parameters
        where the filter and the balance disagree, and ``filter_refusal`` why the filter
        could not answer (then ``filter`` is None).
    """
    truth = result.true_theta
    position_sigma, attitude_sigma = result.measurement_sigma
    convergence = result.convergence_time
    parameters = _block(result.final, convergence, truth)
    for j, name in enumerate(PARAMETER_NAMES):
        if result.status:
            parameters[name]["status"] = result.status[j]
            parameters[name]["source"] = result.answer_source[j]
    balance = result.balance
    nuisance = _nuisance_block(result, config)
    return {
        "parameters": parameters,
        **({"nuisance": nuisance} if nuisance else {}),
        "effects": [fe.as_dict() for fe in result.effects],
        "log_likelihood": _number(result.log_likelihood),
        "filter": None if result.filter_refusal is not None
        else _block(result.filtered, convergence, truth),
        "filter_refusal": result.filter_refusal,
        "balance": None if balance is None else balance.as_dict(),
        "holdout": None if balance is None or balance.holdout is None
        else balance.holdout.as_dict(),
        "mismatch": list(result.mismatch),
        "refined": None if result.refined is None else _block(result.refined, None, truth),
        "prior": _block(result.prior, None, truth),
        "covariance": [[_number(c) for c in row] for row in result.final.covariance],
        "parameter_names": list(result.final.names),
        "log": str(log_path),
        "vehicle": config.name,
        "pose_source": result.pose_source,
        "measurement_sigma": {"position_m": _number(position_sigma),
                              "attitude_rad": _number(attitude_sigma)},
        "noise_met": _noise_met(result),
        "notes": list(result.notes),
        "software": {"name": "mavsysid", "version": software_version()},
    }


def _noise_met(result: EstimationResult) -> dict | None:
    """The noise the filter met on the flight, or None where no filter ran."""
    met = result.noise_met
    if met is None:
        return None
    return {"position_m": _number(met.position_sigma),
            "attitude_rad": _number(met.attitude_sigma),
            "pose_rate_hz": _number(met.pose_rate),
            "force_density": _number(met.force_density),
            "moment_density": _number(met.moment_density)}


def write_estimate_json(
    path: str | Path, result: EstimationResult, config: VehicleConfig, log_path: str | Path
) -> None:
    """Write `result_to_json` to `path` atomically, creating its directory.

    A reader sees the previous file or the complete new one, never a partial write.
    """
    write_json_atomic(path, result_to_json(result, config, log_path))


_NOISE_MET_KEYS = ("position_m", "attitude_rad", "pose_rate_hz", "force_density",
                   "moment_density")


def _estimate_document(path: str | Path) -> tuple[Path, dict, str]:
    """An ``estimate.json`` (or the flight directory holding one) as read: its path, its
    document and the hint that says how to make one; `InputError` in one line."""
    path = Path(path)
    if path.is_dir():
        path = path / "estimate.json"
    hint = f"run `mavsysid estimate LOG -o {path}` on the flight first"
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such estimate; {hint}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"{path}: not a readable estimate.json ({type(error).__name__})") \
            from None
    return path, (document if isinstance(document, dict) else {}), hint


def read_noise_met(path: str | Path) -> NoiseMet:
    """The noise the filter met on a flight, from its ``estimate.json``.

    Parameters
    ----------
    path : str or Path
        An ``estimate.json`` written by `write_estimate_json`, or the flight directory
        holding one (``mavsysid experiment`` writes it there).

    Raises
    ------
    InputError
        No such file, not an estimate, or one without the noise (written before the filter
        recorded it, or one whose filter could not follow the flight): one line.
    """
    return _noise_in(*_estimate_document(path))


def _noise_in(path: Path, document: dict, hint: str) -> NoiseMet:
    """`read_noise_met` of a document already read."""
    met = document.get("noise_met")
    if not isinstance(met, dict):
        raise InputError(f"{path}: holds no noise_met (its filter did not follow the flight, "
                         f"or an older mavsysid wrote it); {hint}")
    values = [met.get(key) for key in _NOISE_MET_KEYS]
    bad = [k for k, v in zip(_NOISE_MET_KEYS, values, strict=True)
           if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0
           or (v == 0 and k in ("position_m", "attitude_rad", "pose_rate_hz"))]
    if bad:
        raise InputError(f"{path}: noise_met.{bad[0]}: a positive number, got {met.get(bad[0])!r}")
    return NoiseMet(*(float(v) for v in values))


def noise_from_flights(paths: Sequence[str | Path]) -> tuple[NoiseMet, tuple[str, ...]]:
    """What earlier flights of a vehicle tell a plan: the noise their filters met (each
    quantity's median, `NoiseMet.median`) and the parameters set aside on at least half
    of them (`read_set_aside`), in θ's order.

    Parameters
    ----------
    paths : sequence of str or Path
        At least one ``estimate.json`` or flight directory holding one.

    Raises
    ------
    InputError
        One of them unusable (`read_noise_met`): one line.
    """
    documents = [_estimate_document(path) for path in paths]
    met = NoiseMet.median([_noise_in(*read) for read in documents])
    counts = Counter(name for _, document, _ in documents for name in _set_aside_in(document))
    return met, tuple(n for n in PARAMETER_NAMES if counts[n] and 2 * counts[n] >= len(paths))


def read_set_aside(path: str | Path) -> tuple[str, ...]:
    """The parameters of θ a flight's filter resolved (σ within `MAX_RELATIVE_SIGMA` of its
    value) that its answer nonetheless did not determine: set aside for a disagreement
    with the force and torque balance, a model mismatch a like flight meets again.

    Parameters
    ----------
    path : str or Path
        An ``estimate.json``, or the flight directory holding one.

    Raises
    ------
    InputError
        No such file or not an estimate: one line.
    """
    return _set_aside_in(_estimate_document(path)[1])


def _set_aside_in(document: dict) -> tuple[str, ...]:
    """`read_set_aside` of a document already read."""
    answer, filtered = document.get("parameters"), document.get("filter")
    if not isinstance(answer, dict) or not isinstance(filtered, dict):
        return ()
    out = []
    for name in PARAMETER_NAMES:
        status = (answer.get(name) or {}).get("status")
        resolved = (filtered.get(name) or {}).get("relative_sigma")
        if (status not in (None, DETERMINED) and isinstance(resolved, (int, float))
                and resolved <= MAX_RELATIVE_SIGMA):
            out.append(name)
    return tuple(out)


def updated_vehicle(config: VehicleConfig, result: EstimationResult) -> VehicleConfig:
    """`config` with the final estimate as its nominal θ and the result's effects.

    The effects (with their fitted values) replace the config's ``[effects.NAME]`` tables,
    so `estimate` and `sim` use them from then on (save with `save_vehicle`).
    """
    updated = config.with_parameters(np.asarray(result.final.theta.value, dtype=float))
    return replace(updated, effects=tuple(fe.effect for fe in result.effects))


#: Columns of the history CSV, in order.
HISTORY_COLUMNS: tuple[str, ...] = (
    "t", *(c for name in PARAMETER_NAMES for c in (name, f"{name}_sigma")), "nis")


def history_frame(history: EstimationHistory) -> pd.DataFrame:
    """The filter's θ and σ over time as a table with `HISTORY_COLUMNS` (N rows)."""
    columns: dict[str, object] = {"t": history.t}
    for j, name in enumerate(PARAMETER_NAMES):
        columns[name] = history.theta[:, j]
        columns[f"{name}_sigma"] = history.theta_sigma[:, j]
    columns["nis"] = history.nis
    return pd.DataFrame(columns, columns=list(HISTORY_COLUMNS))


def write_history_csv(path: str | Path, history: EstimationHistory) -> None:
    """Write `history_frame` as CSV, atomically (a reader never sees half a file).

    Parameters
    ----------
    path : str or Path
        The CSV file; its directory is created.
    history : EstimationHistory
        The filter over time (`mavsysid.estimation.results.EstimationResult.history`).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            history_frame(history).to_csv(f, index=False, float_format="%.17g")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
