"""``estimate --report DIR``: PNG figures, the history CSV and a one-page HTML report.

The page is plain HTML (no script, nothing fetched from the network): a header saying
where the numbers come from, a table of the estimate, the notes, and the figures as
``<img>`` of the PNG files beside it, so the folder can be opened, copied or attached as
it is. `html_page` is shared with ``diagnose --report``
(`mavsysid.discrepancy.report_figures`).

Files written into DIR:

- ``index.html``: the page;
- ``parameters.png``: θ over time with ±σ bands (`plot_parameters`);
- ``innovations.png``: innovations and NIS (`plot_innovations`);
- ``rotor_speeds.png``: the rotor inputs (`plot_rotor_speeds`);
- ``wrench.png``: measured vs model force and torque (`plot_wrench`);
- ``history.csv``: the estimate over time (`mavsysid.estimation.history_table`).
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from mavsysid.estimation.equation_error import AXIS_NAMES
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.history_table import write_history_csv
from mavsysid.estimation.report_figures import (
    plot_innovations,
    plot_parameters,
    plot_rotor_speeds,
    plot_wrench,
)
from mavsysid.estimation.results import EstimationResult
from mavsysid.estimation.wrench_check import compare_wrench
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, VehicleConfig

__all__ = ["ESTIMATE_REPORT_FILES", "ReportTable", "estimate_table", "flight_lines",
           "holdout_table",
           "html_page", "write_estimate_report", "write_index"]

#: What `write_estimate_report` writes, each PNG with its caption on the page.
ESTIMATE_REPORT_FILES: tuple[tuple[str, str], ...] = (
    ("parameters.png", "Parameter estimates over time: the filter with its ±1 σ band, the "
     "refined estimate and the truth (when known)."),
    ("innovations.png", "Filter innovations (measured minus predicted pose) and the NIS; "
     "a consistent filter keeps 95 % of the NIS below the dashed bound."),
    ("rotor_speeds.png", "Rotor speeds as logged: the inputs the model was driven with."),
    ("wrench.png", "Body force and torque the logged motion demands (measured, from the "
     "smoothed pose) against the paper's rotor model at the final estimate."),
)

_STYLE = ("body{font-family:sans-serif;max-width:1150px;margin:1em auto;color:#222}"
          "table{border-collapse:collapse;margin:0.5em 0 1em}"
          "th,td{border:1px solid #bbb;padding:0.2em 0.6em;text-align:right}"
          "th:first-child,td:first-child{text-align:left}"
          "img{max-width:100%;border:1px solid #ddd}figure{margin:1.2em 0}"
          "figcaption{color:#555}")


@dataclass(frozen=True)
class ReportTable:
    """A table of the page: caption, header cells and rows of cell text."""

    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


def _table_html(table: ReportTable) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in table.header)
    body = "\n".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
                     for row in table.rows)
    return (f"<table>\n<caption>{html.escape(table.caption)}</caption>\n"
            f"<tr>{head}</tr>\n{body}\n</table>")


def flight_lines(log_name: str, flight: FlightData, config: VehicleConfig) -> list[str]:
    """The page's first lines, shared by every report: the log and the vehicle."""
    return [f"Log: {log_name}; {len(flight)} samples, {flight.duration:.1f} s.",
            f"Vehicle: {config.name}, mass {config.mass:.4g} kg, {config.rotor_count} rotors."]


def write_index(directory: Path, page: str) -> Path:
    """Write a report's page as ``index.html`` in ``directory``; returns its path."""
    index = directory / "index.html"
    index.write_text(page, encoding="utf-8")
    return index


def html_page(title: str, lines: Sequence[str], tables: Sequence[ReportTable],
              images: Sequence[tuple[str, str]], notes: Sequence[str] = ()) -> str:
    """A self-contained HTML page (no script, no external resource).

    Parameters
    ----------
    title : str
    lines : sequence of str
        Paragraphs under the title (where the numbers come from).
    tables : sequence of ReportTable
    images : sequence of (str, str)
        Image file names relative to the page, each with its caption.
    notes : sequence of str
        Listed under "Notes".

    Returns
    -------
    str
        The page, UTF-8 text; every given string is HTML-escaped.
    """
    parts = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
             f"<title>{html.escape(title)}</title>", f"<style>{_STYLE}</style>", "</head>",
             "<body>", f"<h1>{html.escape(title)}</h1>"]
    parts += [f"<p>{html.escape(line)}</p>" for line in lines]
    parts += [_table_html(t) for t in tables]
    if notes:
        parts += ["<h2>Notes</h2>", "<ul>",
                  *(f"<li>{html.escape(n)}</li>" for n in notes), "</ul>"]
    for name, caption in images:
        parts.append(f'<figure><img src="{html.escape(name, quote=True)}" '
                     f'alt="{html.escape(caption, quote=True)}">'
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def _cell(value: float, spec: str) -> str:
    return format(value, spec) if math.isfinite(value) else "—"


def estimate_table(result: EstimationResult) -> ReportTable:
    """Prior, final estimate, σ, relative σ and convergence per parameter (and the truth)."""
    final, truth = result.final, result.true_theta
    header = ("parameter", "unit", "prior", "estimate", "σ", "σ/|θ| %", "converged s")
    if truth is not None:
        header += ("true", "error %")
    if result.status:
        header += ("status", "from")
    rows = []
    for j, name in enumerate(PARAMETER_NAMES):
        value, sigma = float(final.value[j]), float(final.sigma[j])
        row = (name, PARAMETER_UNITS[name], _cell(float(result.prior.value[j]), ".4e"),
               _cell(value, ".4e"), _cell(sigma, ".2e"),
               _cell(100.0 * sigma / abs(value) if value else math.nan, ".2f"),
               _cell(float(result.convergence_time[j]), ".2f"))
        if truth is not None:
            true = float(truth[j])
            row += (_cell(true, ".4e"),
                    _cell(100.0 * (value - true) / abs(true) if true else math.nan, "+.2f"))
        if result.status:
            row += (result.status[j], result.answer_source[j])
        rows.append(row)
    which = "batch refinement" if result.refined is not None else "filter"
    if result.status:
        which = "per parameter"
    return ReportTable(f"Estimate ({which}), SI", header, tuple(rows))


def holdout_table(result: EstimationResult) -> ReportTable | None:
    """The held-out check of the force and torque balance: RMSE per axis and its ratio to
    the prior model's; None without one.

    Parameters
    ----------
    result : EstimationResult
        The estimate; its balance carries the held-out check.
    """
    holdout = None if result.balance is None else result.balance.holdout
    if holdout is None:
        return None
    rows = tuple((axis, _cell(float(m), ".3g"), _cell(float(p), ".3g"), _cell(float(r), ".2f"))
                 for axis, m, p, r in zip(AXIS_NAMES, holdout.rmse, holdout.prior_rmse,
                                          holdout.ratio, strict=True))
    rows += (("force (pooled)", "", "", _cell(holdout.force_ratio, ".2f")),
             ("angular acceleration (pooled)", "", "", _cell(holdout.torque_ratio, ".2f")))
    return ReportTable(
        f"Held-out check: fitted before t = {holdout.start:.2f} s, the rest predicted "
        f"({holdout.rows} rows); RMSE in m/s² and rad/s²; ratio below 1: better than the prior",
        ("axis", "RMSE", "prior RMSE", "ratio"), rows)


def write_estimate_report(directory: str | Path, result: EstimationResult,
                          flight: FlightData, config: VehicleConfig, log_name: str) -> Path:
    """Write the report folder (module docstring) and return the path of ``index.html``.

    Parameters
    ----------
    directory : str or Path
        Created if missing; the report's files in it are replaced.
    result : EstimationResult
    flight : FlightData
        The flight as estimated from (rotor speeds, pose).
    config : VehicleConfig
        Mass and geometry (for the force and torque comparison).
    log_name : str
        How to name the log on the page.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    plot_parameters(result, directory / "parameters.png")
    plot_innovations(result, directory / "innovations.png")
    plot_rotor_speeds(flight, directory / "rotor_speeds.png")
    plot_wrench(compare_wrench(flight, config, result.final.value), directory / "wrench.png")
    write_history_csv(directory / "history.csv", result.history)
    position_sigma, attitude_sigma = result.measurement_sigma
    lines = [
        *flight_lines(log_name, flight, config),
        f"Pose source: {result.pose_source.replace('_', ' ')}; measurement σ assumed "
        f"{1e3 * position_sigma:.2f} mm, {math.degrees(attitude_sigma):.3f}°.",
        "The estimate over time is in history.csv (t, each parameter and its σ, NIS).",
    ]
    tables = [estimate_table(result)]
    holdout = holdout_table(result)
    if holdout is not None:
        tables.append(holdout)
    page = html_page(f"Parameter estimate: {log_name}", lines, tables,
                     ESTIMATE_REPORT_FILES, result.notes)
    return write_index(directory, page)
