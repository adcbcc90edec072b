"""The figures of ``estimate --report DIR``, as PNG files (matplotlib, no display needed).

Each function draws one figure and writes it. Figures are made with
`matplotlib.figure.Figure` directly (not pyplot), so nothing global changes: no backend
is selected, no window opens and nothing is left open; saving renders through Agg.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.results import EstimationResult
from mavsysid.estimation.wrench_check import WrenchComparison
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS
from scipy.stats import chi2

__all__ = ["DPI", "plot_innovations", "plot_parameters", "plot_rotor_speeds", "plot_wrench",
           "save_figure"]

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
