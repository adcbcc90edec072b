"""The evaluation's figures: PNG (matplotlib) and a Rerun recording.

* ``convergence.png`` — median and 95 % band of estimate / truth over flight time, per
  parameter, for each planner (the paper's Fig. "stat_summary");
* ``error_vs_sigma.png`` — final relative error against final relative σ, per parameter
  (the paper's Fig. "stat_sigma").
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.experiments.evaluation import EvaluationSummary
from mavsysid.formats.rerun_file import atomic_recording
from mavsysid.vehicle.config import PARAMETER_NAMES

__all__ = ["write_evaluation_pngs", "write_evaluation_rrd"]

_COLORS = {"dopt": "tab:blue", "random": "tab:orange"}
_LABELS = {"dopt": "DOPT-COV", "random": "RAND"}


def write_evaluation_pngs(out: str | Path, summary: EvaluationSummary,
                          records: list[dict[str, Any]]) -> list[Path]:
    """Write the two figures into ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    paths = [out / "convergence.png", out / "error_vs_sigma.png"]
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), sharex=True, constrained_layout=True)
    for j, (ax, name) in enumerate(zip(axes.flat, PARAMETER_NAMES, strict=True)):
        for kind in summary.kinds:
            lo, mid, hi = summary.ratio_percentiles[kind][:, :, j]
            color = _COLORS.get(kind)
            ax.fill_between(summary.t, lo, hi, color=color, alpha=0.2, linewidth=0)
            ax.plot(summary.t, mid, color=color, label=_LABELS.get(kind, kind))
        ax.axhspan(0.95, 1.05, color="0.85", zorder=0)
        ax.set_ylim(0.4, 1.6)
        ax.set_title(name)
        if j >= 3:
            ax.set_xlabel("flight time (s)")
    axes[0, 0].set_ylabel("estimate / truth")
    axes[1, 0].set_ylabel("estimate / truth")
    axes[0, 0].legend(loc="upper right")
    fig.suptitle(f"Median and 95 % of the EKF estimates over {summary.experiments} experiments")
    fig.savefig(paths[0], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), constrained_layout=True)
    for j, (ax, name) in enumerate(zip(axes.flat, PARAMETER_NAMES, strict=True)):
        for kind in summary.kinds:
            flights = [max((f for f in r["flights"] if f["kind"] == kind),
                           key=lambda f: f["iteration"]) for r in records]
            sigma = [f["relative_sigma"][j] for f in flights]
            error = [abs(f["relative_error"][j]) for f in flights]
            ax.scatter(sigma, error, s=14, color=_COLORS.get(kind),
                       label=_LABELS.get(kind, kind))
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(name)
        ax.set_xlabel("final relative σ")
    axes[0, 0].set_ylabel("|relative error|")
    axes[1, 0].set_ylabel("|relative error|")
    axes[0, 0].legend()
    fig.suptitle("Final relative error vs final σ")
    fig.savefig(paths[1], dpi=110)
    plt.close(fig)
    return paths


def write_evaluation_rrd(path: str | Path, summary: EvaluationSummary) -> None:
    """The median and 95 % band of estimate / truth over flight time, as Rerun series."""
    import rerun as rr

    with atomic_recording(path, "mavsysid-evaluate", "evaluation", "evaluation") as rec:
        time = rr.TimeColumn("flight_time", duration=summary.t)
        for kind in summary.kinds:
            for j, name in enumerate(PARAMETER_NAMES):
                for level, label in enumerate(("p2.5", "median", "p97.5")):
                    values = np.ascontiguousarray(summary.ratio_percentiles[kind][level, :, j])
                    rec.send_columns(f"evaluation/{kind}/{name}/{label}", indexes=[time],
                                     columns=rr.Scalars.columns(scalars=values))
