"""``estimate --report DIR``: PNG figures, the history CSV and a one-page HTML report.

Figures are made with `matplotlib.figure.Figure` directly (not pyplot), so nothing global
changes: no backend is selected, no window opens; saving renders through Agg. The page is
plain HTML (no script, nothing fetched from the network) with the figures as ``<img>`` of
the PNG files beside it, so the folder can be opened, copied or attached as it is;
`html_page` is shared with ``diagnose --report``. The model-against-measurement figure
(`compare_wrench`) shows the force and torque balance's own rows at the final θ: the
measured wrench and the paper's model's, through one smoother, in N and N·m.

Files written into DIR (`ESTIMATE_REPORT_FILES`): ``index.html``; ``parameters.png`` (θ over
time with ±σ bands); ``innovations.png`` (innovations and NIS); ``rotor_speeds.png`` (the
rotor inputs); ``wrench.png`` (model against measurement); ``history.csv``.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from mavsysid.estimation.balance.fit import WrenchComparison, compare_wrench
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.report.text import write_history_csv
from mavsysid.estimation.results import AXIS_NAMES, EstimationResult
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, VehicleConfig
from scipy.stats import chi2

__all__ = ["DPI", "ESTIMATE_REPORT_FILES", "ReportTable", "estimate_table", "flight_lines",
           "holdout_table", "html_page", "plot_innovations", "plot_parameters",
           "plot_rotor_speeds", "plot_wrench", "save_figure", "write_estimate_report",
           "write_index"]


#: Resolution of the written PNGs, dots per inch (a 10-inch-wide figure is 1000 px).
DPI = 100

_AXIS_COLORS = ("tab:red", "tab:green", "tab:blue")


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG to ``path`` (directory created) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png", dpi=DPI)
    return path


def plot_parameters(result: EstimationResult, path: str | Path) -> Path:
    """θ_j of the filter over time with its ±σ band, one panel per parameter.

    Also the truth (when known) and the refined estimate (when refinement ran) as
    horizontal lines; each panel's y axis is in the parameter's SI unit.
    """
    h = result.history
    t = h.t
    fig = Figure(figsize=(11, 8), layout="constrained")
    axes = fig.subplots(3, 2, sharex=True).ravel()
    for j, (ax, name) in enumerate(zip(axes, PARAMETER_NAMES, strict=True)):
        value, sigma = h.theta[:, j], h.theta_sigma[:, j]
        ax.fill_between(t, value - sigma, value + sigma, color="tab:blue", alpha=0.25,
                        linewidth=0, label="filter ± σ")
        ax.plot(t, value, color="tab:blue", linewidth=1.2, label="filter")
        if result.true_theta is not None:
            ax.axhline(result.true_theta[j], color="tab:green", linestyle="--", label="true")
        if result.refined is not None:
            ax.axhline(result.refined.value[j], color="tab:red", linestyle=":",
                       label="refined")
        ax.set_title(name)
        ax.set_ylabel(PARAMETER_UNITS[name])
        ax.grid(alpha=0.3)
    for ax in axes[-2:]:
        ax.set_xlabel("log time, s")
    axes[0].legend(loc="upper right", fontsize="small")
    fig.suptitle("Parameter estimates over time (filter ± 1 σ)")
    return save_figure(fig, path)


def plot_innovations(result: EstimationResult, path: str | Path) -> Path:
    """Position and attitude innovations per axis, and the NIS with its χ²(6) 95 % bound."""
    h = result.history
    t = h.t
    fig = Figure(figsize=(11, 8), layout="constrained")
    ax_p, ax_a, ax_n = fig.subplots(3, 1, sharex=True)
    for i, (axis, color) in enumerate(zip("xyz", _AXIS_COLORS, strict=True)):
        ax_p.plot(t, 1e3 * h.innovation[:, i], color=color, linewidth=0.7, label=axis)
        ax_a.plot(t, np.degrees(h.innovation[:, 3 + i]), color=color, linewidth=0.7,
                  label=axis)
    position_sigma, attitude_sigma = result.measurement_sigma
    ax_p.set_ylabel("position, mm")
    ax_p.set_title(f"position innovation (measurement σ {1e3 * position_sigma:.2g} mm)")
    ax_a.set_ylabel("attitude, °")
    ax_a.set_title(f"attitude innovation (measurement σ {math.degrees(attitude_sigma):.2g}°)")
    # A consistent filter's NIS is χ² with 6 degrees of freedom (3 position + 3 attitude).
    bound = float(chi2.ppf(0.95, df=6))
    ax_n.plot(t, h.nis, color="tab:blue", linewidth=0.7, label="NIS")
    ax_n.axhline(bound, color="tab:red", linestyle="--", label=f"χ²(6) 95 % = {bound:.1f}")
    # Linear, and cut at the bulk: the first steps' NIS can be orders of magnitude off.
    top = max(bound, float(np.percentile(h.nis, 99))) if h.nis.size else bound
    ax_n.set_ylim(0.0, 1.5 * top)
    ax_n.set_ylabel("NIS")
    ax_n.set_xlabel("log time, s")
    inside = float(np.mean(h.nis <= bound)) if h.nis.size else math.nan
    ax_n.set_title(f"normalised innovation squared ({100 * inside:.0f} % below the bound)")
    for ax in (ax_p, ax_a, ax_n):
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize="small", ncol=3)
    fig.suptitle("Filter innovations")
    return save_figure(fig, path)


def plot_rotor_speeds(flight: FlightData, path: str | Path) -> Path:
    """The logged rotor speeds over time, rad/s, one line per rotor (config order)."""
    t = flight.t
    n = np.asarray(flight.rotor_speeds, float)
    fig = Figure(figsize=(11, 4), layout="constrained")
    ax = fig.subplots()
    for i in range(n.shape[1]):
        ax.plot(t, n[:, i], linewidth=0.8, label=f"n{i + 1}")
    ax.set_xlabel("log time, s")
    ax.set_ylabel("rotor speed, rad/s")
    ax.set_title("Rotor speeds (inputs), in the vehicle config's rotor order")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize="small", ncol=min(n.shape[1], 8))
    return save_figure(fig, path)


def _wrench_panel(ax: Axes, t: np.ndarray, measured: np.ndarray, model: np.ndarray,
                  title: str, unit: str) -> None:
    rms = float(np.sqrt(np.mean((measured - model) ** 2))) if t.size else math.nan
    ax.plot(t, measured, color="black", linewidth=0.8, label="measured")
    ax.plot(t, model, color="tab:orange", linewidth=0.8, label="model")
    ax.set_title(f"{title} (RMS difference {rms:.3g} {unit})")
    ax.set_ylabel(unit)
    ax.grid(alpha=0.3)


def plot_wrench(comparison: WrenchComparison, path: str | Path) -> Path:
    """Measured against model body force (left) and torque (right), per axis."""
    c = comparison
    t = c.t
    fig = Figure(figsize=(11, 8), layout="constrained")
    axes = fig.subplots(3, 2, sharex=True)
    for i, axis in enumerate("xyz"):
        _wrench_panel(axes[i, 0], t, c.measured_force[:, i], c.model_force[:, i],
                      f"force {axis}", "N")
        _wrench_panel(axes[i, 1], t, c.measured_torque[:, i], c.model_torque[:, i],
                      f"torque {axis}", "N·m")
    for ax in axes[-1]:
        ax.set_xlabel("log time, s")
    axes[0, 0].legend(loc="upper right", fontsize="small")
    fig.suptitle("Body force and torque: measured (from the pose) vs the model at the "
                 "estimate")
    return save_figure(fig, path)


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
    choices = None if result.balance is None else result.balance.choices
    fit = {} if choices is None else {"window": choices.window, "delay": choices.delay}
    plot_wrench(compare_wrench(flight, config, result.final.theta.value, **fit),
                directory / "wrench.png")
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
