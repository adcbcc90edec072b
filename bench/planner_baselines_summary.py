"""The summary of `bench/planner_baselines.py`: figures with 95 % paired-bootstrap intervals
over seeds, the planner's targets with pass/fail, and their text form.

Every figure compares kinds on the same seeds (same prior draw, same true vehicle, same
noise seed), so intervals resample seeds in pairs. "dopt" is the planned flight (re-planned
in flight); D-opt ratios are baseline over planned (> 1: planned better; D-opt is
det(Σ)^(1/6), smaller is better).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from mavsysid.experiments.evaluation import median_convergence_time
from mavsysid.experiments.evaluation_intervals import OFF_PATH_RMS, SATURATED_SHARE
from mavsysid.vehicle.config import PARAMETER_NAMES
from scipy.stats import bootstrap

__all__ = ["PLANNED", "column", "format_summary", "interval", "summarize"]

#: The kind every other is compared with.
PLANNED = "dopt"
#: The planner's targets (docs/benchmarks.md).
RANDOM_RATIO, PRACTITIONER_RATIO, FLIGHT_TIME_RATIO, SIGMA_TOLERANCE = 5.0, 2.0, 3.0, 0.25
SATURATING_SHARE_ALLOWED = 1.0 / 20.0


def interval(samples: tuple[np.ndarray, ...], statistic: Callable) -> list[float]:
    """95 % percentile bootstrap interval over seeds (samples resampled in pairs)."""
    if samples[0].shape[0] < 2:
        return [float("nan"), float("nan")]
    with np.errstate(invalid="ignore"):  # inf seconds (never reached) in a resample
        result = bootstrap(samples, statistic, paired=True, vectorized=False,
                           n_resamples=2000, method="percentile", rng=np.random.default_rng(0))
    return [float(result.confidence_interval.low), float(result.confidence_interval.high)]


def column(rows: list[dict], kind: str, key: str) -> np.ndarray:
    """One figure of one kind over seeds, shape (seeds,) (or (seeds, 6)); NaN: inf."""
    return np.array([np.inf if r[kind][key] is None else r[kind][key] for r in rows],
                    dtype=float)


def dopt_ratios(rows: list[dict], others: Sequence[str]) -> dict:
    """Reached D-opt of each kind over the planned flight's, and the truth's prediction."""
    planned = column(rows, PLANNED, "reached")
    out = {}
    for kind in others:
        other = column(rows, kind, "reached")
        out[kind] = {
            "ratio_of_medians": float(np.median(other) / np.median(planned)),
            "ratio_of_medians_ci95": interval((other, planned),
                                              lambda a, b: np.median(a) / np.median(b)),
            "median_ratio": float(np.median(other / planned)),
            "median_ratio_ci95": interval((other / planned,), np.median),
            "predicted_ratio": float(np.median(column(rows, kind, "predicted"))
                                     / np.median(column(rows, PLANNED, "predicted"))),
        }
    return out


def flyability(rows: list[dict], kinds: Sequence[str]) -> dict:
    """Saturating and off-path flights, median saturated share, median |error| per kind."""
    out = {}
    planned_error = column(rows, PLANNED, "error")
    for kind in kinds:
        sat, rms = column(rows, kind, "saturated"), column(rows, kind, "rms")
        error = column(rows, kind, "error")
        out[kind] = {
            "saturating": int(np.sum(sat > SATURATED_SHARE)),
            "off_path": int(np.sum(rms > OFF_PATH_RMS)),
            "median_saturated_share": float(np.median(sat)),
            "median_error": np.median(error, axis=0).tolist(),
            # planned minus this kind: < 0 where the planned flight's error is smaller.
            "error_difference_ci95": [interval((planned_error[:, j], error[:, j]),
                                               lambda a, b: np.median(a) - np.median(b))
                                      for j in range(6)] if kind != PLANNED else None,
        }
    return out


def sigma_prediction(rows: list[dict], kinds: Sequence[str]) -> dict:
    """Median over seeds of predicted / reached relative σ per parameter, with intervals."""
    out = {}
    for kind in kinds:
        ratio = column(rows, kind, "predicted_sigma") / column(rows, kind, "reached_sigma")
        out[kind] = {"median_ratio": np.median(ratio, axis=0).tolist(),
                     "ci95": [interval((ratio[:, j],), np.median) for j in range(6)]}
    return out


def efficiency(rows: list[dict], kinds: Sequence[str], budget: float,
               truth: np.ndarray) -> dict:
    """Seconds to the planned D-opt, seconds to σ/θ ≤ 1 %, the paper's convergence column."""
    out = {}
    for kind in kinds:
        sec = column(rows, kind, "to_planned")
        sec = np.where(np.isnan(sec), np.inf, sec)
        to_1 = column(rows, kind, "to_1pct")
        done = to_1[np.isfinite(to_1)]
        out[kind] = {
            "to_planned_median": float(np.median(sec)),
            "to_planned_ci95": interval((sec,), np.median),
            "to_planned_budgets": float(np.median(sec) / budget),
            "to_1pct_median": float(np.median(done)) if done.size else float("nan"),
            "to_1pct_never": int(np.sum(~np.isfinite(to_1))),
            "paper_convergence": paper_column(rows, kind, truth),
        }
    return out


def paper_column(rows: list[dict], kind: str, truth: np.ndarray) -> list[float] | None:
    """The paper's convergence time of the median estimate within 5 %, s, per parameter."""
    histories = [r[kind].get("history") for r in rows]
    if any(h is None for h in histories):
        return None
    length = max(len(h["t"]) for h in histories)
    ratios = np.empty((len(rows), length, 6))
    for i, h in enumerate(histories):
        theta = np.asarray(h["theta"])
        ratios[i, :len(theta)], ratios[i, len(theta):] = theta, theta[-1]
    return median_convergence_time(np.arange(length) / 10.0, ratios / truth).tolist()


def tool_estimates(rows: list[dict], kinds: Sequence[str]) -> dict:
    """The tool's answer (``--estimator``) per kind scored by it: median |error| over the
    flights not refused, refusals, share of flights whose 95 % interval covers the truth."""
    out = {}
    for kind in kinds:
        if "tool_error" not in rows[0][kind]:
            continue
        error = np.array([[np.nan if e is None else e for e in r[kind]["tool_error"]]
                          for r in rows], dtype=float)
        covered = np.array([r[kind]["tool_covered"] for r in rows], dtype=bool)
        out[kind] = {"median_error": np.nanmedian(error, axis=0).tolist(),
                     "refused": int(sum(r[kind]["tool_refused"] is not None for r in rows)),
                     "covered_share": covered.mean(axis=0).tolist()}
    return out


def targets(summary: dict, n: int) -> dict:
    """The planner's acceptance targets, each with its figure and whether it is met."""
    fly, ratio = summary["flyability"], summary["dopt_ratio"]
    eff, sig = summary["efficiency"], summary["sigma_prediction"][PLANNED]["median_ratio"]
    no_worse = all(a <= b for a, b in zip(fly[PLANNED]["median_error"],
                                          fly["practitioner"]["median_error"], strict=True))
    return {
        "saturating_planned": [fly[PLANNED]["saturating"],
                               fly[PLANNED]["saturating"] <= SATURATING_SHARE_ALLOWED * n],
        "vs_random": [ratio["random"]["ratio_of_medians"],
                      ratio["random"]["ratio_of_medians"] >= RANDOM_RATIO],
        "vs_practitioner": [ratio["practitioner"]["ratio_of_medians"],
                            ratio["practitioner"]["ratio_of_medians"] >= PRACTITIONER_RATIO],
        "error_no_worse_than_practitioner": [None, no_worse],
        "practitioner_flight_time": [eff["practitioner"]["to_planned_budgets"],
                                     eff["practitioner"]["to_planned_budgets"]
                                     >= FLIGHT_TIME_RATIO],
        "sigma_prediction": [sig, all(abs(r - 1.0) <= SIGMA_TOLERANCE for r in sig)],
        **_tool_target(summary.get("tool_estimates", {})),
    }


def _tool_target(tool: dict) -> dict:
    """The error target judged on the tool's answer, when both kinds were scored by it."""
    if PLANNED not in tool or "practitioner" not in tool:
        return {}
    no_worse = all(a <= b for a, b in zip(tool[PLANNED]["median_error"],
                                          tool["practitioner"]["median_error"], strict=True))
    return {"tool_error_no_worse_than_practitioner": [None, no_worse]}


def summarize(rows: list[dict], kinds: Sequence[str], budget: float, max_passes: int,
              truth: np.ndarray) -> dict:
    """Every figure of the bench as a JSON-ready dict (see the module docstring)."""
    ok = [r for r in rows if "failed" not in r]
    summary: dict = {"seeds": len(rows), "completed": len(ok), "budget": budget,
                     "max_passes": max_passes, "parameters": list(PARAMETER_NAMES),
                     "failed": [{"seed": r["seed"], "reason": r["failed"]}
                                for r in rows if "failed" in r]}
    if not ok:
        return summary
    summary["dopt_ratio"] = dopt_ratios(ok, [k for k in kinds if k != PLANNED])
    summary["flyability"] = flyability(ok, kinds)
    summary["sigma_prediction"] = sigma_prediction(ok, kinds)
    summary["efficiency"] = efficiency(ok, kinds, budget, np.asarray(truth, dtype=float))
    summary["tool_estimates"] = tool_estimates(ok, kinds)
    summary["opening_refused"] = sum(bool(r[PLANNED].get("opening_refused")) for r in ok)
    summary["targets"] = targets(summary, len(ok))
    return summary


def _ci(pair: list[float], digits: str = ".2f") -> str:
    return f"({pair[0]:{digits}}–{pair[1]:{digits}})"


def format_summary(summary: dict) -> str:
    """The summary as the bench's text tables."""
    lines = [f"{summary['completed']} of {summary['seeds']} seeds completed"]
    lines += [f"  seed {f['seed']} failed: {f['reason']}" for f in summary["failed"]]
    if not summary["completed"]:
        return "\n".join(lines)
    lines.append("reached D-opt, kind / planned (> 1: planned better): ratio of medians "
                 "(95 % paired bootstrap), median paired ratio (95 %), predicted with true θ")
    for kind, r in summary["dopt_ratio"].items():
        lines.append(f"  {kind:<18} {r['ratio_of_medians']:6.2f} {_ci(r['ratio_of_medians_ci95'])}"
                     f"  {r['median_ratio']:6.2f} {_ci(r['median_ratio_ci95'])}"
                     f"  predicted {r['predicted_ratio']:.2f}")
    lines.append(f"flyability: flights saturating > {100 * SATURATED_SHARE:g} % of ticks, "
                 f"> {OFF_PATH_RMS:g} m RMS off path, median saturated share")
    for kind, f in summary["flyability"].items():
        lines.append(f"  {kind:<18} {f['saturating']}, {f['off_path']}, "
                     f"{f['median_saturated_share']:.1%}")
    lines.append("median |error| / θ (%): " + ", ".join(summary["parameters"])
                 + "; [planned − kind, 95 %, pp]")
    for kind, f in summary["flyability"].items():
        diff = f["error_difference_ci95"]
        extra = "" if diff is None else "  [" + " ".join(
            f"{100 * a:+.2f}..{100 * b:+.2f}" for a, b in diff) + "]"
        lines.append(f"  {kind:<18} " + "  ".join(f"{100 * e:.3f}" for e in f["median_error"])
                     + extra)
    lines.append("predicted σ (planner's recursion at the θ planned with, along the flown "
                 "path) / filter σ, relative; median over seeds per parameter")
    for kind, s in summary["sigma_prediction"].items():
        lines.append(f"  {kind:<18} " + "  ".join(f"{r:.2f}" for r in s["median_ratio"]))
    lines.append(f"seconds of flight to reach the planned flight's D-opt (median, 95 %; inf: "
                 f"not within {summary['max_passes']} repetitions); σ/θ ≤ 1 % (filter); the "
                 "paper's convergence column (median estimate within 5 %, s)")
    for kind, e in summary["efficiency"].items():
        paper = e["paper_convergence"]
        lines.append(f"  {kind:<18} {e['to_planned_median']:7.1f} s "
                     f"{_ci(e['to_planned_ci95'], '.1f')} = {e['to_planned_budgets']:.2f}× "
                     f"budget | 1 %: {e['to_1pct_median']:6.2f} s, {e['to_1pct_never']} never"
                     + ("" if paper is None else " | " + " ".join(f"{c:.2f}" for c in paper)))
    if summary["tool_estimates"]:
        lines.append("the tool's answer (--estimator): median |error| / θ (%) over flights not "
                     "refused; refused; 95 % interval covers the truth (% of flights)")
    for kind, t in summary["tool_estimates"].items():
        lines.append(f"  {kind:<18} " + "  ".join(f"{100 * e:.3f}" for e in t["median_error"])
                     + f" | refused {t['refused']} | covers "
                     + " ".join(f"{100 * c:.0f}" for c in t["covered_share"]))
    lines.append(f"the opening's estimate refused (rest planned from the prior): "
                 f"{summary.get('opening_refused', 0)} of {summary['completed']}")
    lines.append("targets: figure, met")
    for name, (value, met) in summary["targets"].items():
        shown = ("" if value is None else " ".join(f"{v:.2f}" for v in value)
                 if isinstance(value, list) else f"{value:.3g}")
        lines.append(f"  {name:<34} {shown:<32} {'yes' if met else 'NO'}")
    return "\n".join(lines)
