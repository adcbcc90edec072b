"""``diagnose --report DIR``: PNG figures and a one-page HTML report of a diagnosis.

Files written into DIR (the page is plain HTML, no script, nothing fetched; built by
`mavsysid.estimation.report.figures.html_page`):

- ``index.html``: the named effects, the gap per axis, the notes and the figures;
- ``residuals.png``: the residual per axis before and after the named effects, with the
  start of the held-out part marked (`plot_residuals`);
- ``rotor_speeds.png``: the rotor inputs;
- ``wrench.png``: measured vs model body force and torque at the diagnosed θ, the paper's
  model without effects (`mavsysid.estimation.report.figures`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from mavsysid.discrepancy.diagnosis import Diagnosis
from mavsysid.discrepancy.residuals import AXIS_NAMES, AXIS_UNITS
from mavsysid.estimation import (
    FlightData,
    ReportTable,
    compare_wrench,
    flight_lines,
    html_page,
    plot_rotor_speeds,
    plot_wrench,
    save_figure,
    write_index,
)
from mavsysid.vehicle.config import VehicleConfig

__all__ = ["DIAGNOSIS_REPORT_FILES", "effects_table", "gap_table", "plot_residuals",
           "write_diagnosis_report"]

#: The PNGs `write_diagnosis_report` writes, each with its caption on the page.
DIAGNOSIS_REPORT_FILES: tuple[tuple[str, str], ...] = (
    ("residuals.png", "Measured minus model acceleration per axis, before (the identified "
     "model) and after adding the named effects; right of the dashed line is the held-out "
     "part, kept out of all fitting."),
    ("rotor_speeds.png", "Rotor speeds as logged: the inputs the model was driven with."),
    ("wrench.png", "Body force and torque the logged motion demands (measured, from the "
     "smoothed pose) against the paper's rotor model at the diagnosed θ, without effects."),
)


def plot_residuals(diagnosis: Diagnosis, path: str | Path) -> Path:
    """Residual per axis before and after the named effects, one panel per axis."""
    d = diagnosis
    used = d.used
    t = d.t[used]
    fig = Figure(figsize=(11, 8), layout="constrained")
    axes = fig.subplots(3, 2, sharex=True)
    for a, (name, unit) in enumerate(zip(AXIS_NAMES, AXIS_UNITS, strict=True)):
        ax = axes[a % 3, a // 3]
        ax.plot(t, d.residual_before[used, a], color="tab:red", linewidth=0.7,
                label="before")
        ax.plot(t, d.residual_after[used, a], color="tab:blue", linewidth=0.7,
                label="after")
        ax.axvline(d.split_time, color="black", linestyle="--", linewidth=0.8)
        ax.set_title(f"{name}: held-out RMS {d.gap.before.rms[a]:.3g} → "
                     f"{d.gap.after.rms[a]:.3g} {unit}")
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("log time, s")
    axes[0, 0].legend(loc="upper right", fontsize="small")
    named = ", ".join(e.effect.name for e in d.effects) or "none"
    fig.suptitle(f"Residuals before and after the named effects ({named})")
    return save_figure(fig, path)


def effects_table(diagnosis: Diagnosis) -> ReportTable:
    """One row per parameter of each named effect: value, σ, 95 % interval, ΔBIC."""
    rows = []
    for fe in diagnosis.effects:
        for j, p in enumerate(fe.effect.parameters):
            lo, hi = fe.ci95[j]
            rows.append((fe.effect.name, p.name, p.unit, f"{fe.effect.values[j]:.4g}",
                         f"{fe.sigma[j]:.2g}", f"[{lo:.4g}, {hi:.4g}]",
                         f"{fe.delta_bic:.1f}"))
    caption = ("Named effects, most important first" if rows
               else "Named effects: none (no significant discrepancy)")
    return ReportTable(caption, ("effect", "parameter", "unit", "value", "σ",
                                 "95 % interval", "ΔBIC"), tuple(rows))


def gap_table(diagnosis: Diagnosis) -> ReportTable:
    """Held-out residual RMS and Ljung–Box p per axis, before and after."""
    g = diagnosis.gap
    rows = tuple(
        (name, unit, f"{g.before.rms[a]:.4g}", f"{g.after.rms[a]:.4g}",
         f"{g.before.ljung_box_p[a]:.2g}", f"{g.after.ljung_box_p[a]:.2g}")
        for a, (name, unit) in enumerate(zip(AXIS_NAMES, AXIS_UNITS, strict=True)))
    caption = (f"The gap on the held-out part (from t = {diagnosis.split_time:.2f} s): "
               f"{100 * g.shrink:.0f} % smaller on the flagged axes")
    return ReportTable(caption, ("axis", "unit", "RMS before", "RMS after",
                                 "Ljung–Box p before", "p after"), rows)


def write_diagnosis_report(directory: str | Path, diagnosis: Diagnosis, flight: FlightData,
                           config: VehicleConfig, log_name: str) -> Path:
    """Write the report folder (module docstring) and return the path of ``index.html``.

    Parameters
    ----------
    directory : str or Path
        Created if missing; the report's files in it are replaced.
    diagnosis : Diagnosis
    flight : FlightData
        The flight as diagnosed (rotor speeds, pose).
    config : VehicleConfig
        Mass and geometry.
    log_name : str
        How to name the log on the page.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    plot_residuals(diagnosis, directory / "residuals.png")
    plot_rotor_speeds(flight, directory / "rotor_speeds.png")
    theta = np.asarray(diagnosis.theta_identified, float)
    plot_wrench(compare_wrench(flight, config, theta), directory / "wrench.png")
    lines = [
        *flight_lines(log_name, flight, config),
        "Residual axes: body specific force f (m/s²) and angular acceleration dω (rad/s²).",
    ]
    page = html_page(f"Model diagnosis: {log_name}", lines,
                     [effects_table(diagnosis), gap_table(diagnosis)],
                     DIAGNOSIS_REPORT_FILES, diagnosis.notes)
    return write_index(directory, page)
