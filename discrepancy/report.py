"""The diagnosis as text for a person and as JSON (docs/architecture.md's diagnose contract)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.discrepancy.diagnosis import Diagnosis
from mavsysid.discrepancy.residual_stats import NIS_BAND
from mavsysid.discrepancy.residuals import AXIS_NAMES, AXIS_UNITS
from mavsysid.formats.flight_dir import write_json_atomic
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, vehicle_to_toml

__all__ = [
    "AXIS_LABELS",
    "augmented_vehicle",
    "diagnosis_to_json",
    "format_diagnosis",
    "format_reestimate",
    "write_diagnosis_json",
]

#: Plain-language axis names for the text report.
AXIS_LABELS = ("force x (forward)", "force y (left)", "force z (up)",
               "roll acceleration", "pitch acceleration", "yaw acceleration")


def _num(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def augmented_vehicle(config: VehicleConfig, diagnosis: Diagnosis) -> VehicleConfig:
    """The vehicle config carrying the augmented model: known and named effects.

    θ stays the config's prior; ``estimate`` fits θ and the effects' parameters together.
    """
    return replace(config, effects=tuple(diagnosis.augmented_effects))


def _p(value: float) -> str:
    return "n/a" if not math.isfinite(value) else ("<0.001" if value < 1e-3 else f"{value:.3f}")


def _effect_lines(diagnosis: Diagnosis) -> list[str]:
    lines = []
    for i, f in enumerate(diagnosis.effects, 1):
        e = f.effect
        lines.append(f"  {i}. {e.name} — {e.title}: {e.description}.")
        for j, p in enumerate(e.parameters):
            lo, hi = f.ci95[j]
            lines.append(f"       {p.name} = {e.values[j]:.4g} {p.unit}   95 % CI "
                         f"[{lo:.4g}, {hi:.4g}]   ({p.description})")
        lines.append(f"       evidence: BIC lowered by {-f.delta_bic:.0f}; likelihood-ratio "
                     f"p {_p(f.p_value)}")
    for tie in diagnosis.ties:
        alts = ", ".join(f"{a} (BIC only {g:.1f} worse)" for a, g in
                         zip(tie.alternatives, tie.delta_bic_gap, strict=True))
        lines.append(f"  Note: {alts} explains the residual about as well as {tie.chosen}; "
                     "the data cannot tell them apart reliably.")
    return lines


def _gap_lines(diagnosis: Diagnosis) -> list[str]:
    g = diagnosis.gap
    head = "  axis                       unit     before    after   Ljung–Box p before → after"
    lines = [head]
    for a, (label, unit) in enumerate(zip(AXIS_LABELS, AXIS_UNITS, strict=True)):
        mark = "*" if a in g.flagged_axes else " "
        lines.append(f" {mark}{label:26s} {unit:7s} {g.before.rms[a]:8.4f} {g.after.rms[a]:8.4f}"
                     f"   {_p(g.before.ljung_box_p[a]):>6s} → {_p(g.after.ljung_box_p[a])}")
    if g.held_out is not None:
        (fb, tb), (fa, ta) = g.held_out.ratios("before"), g.held_out.ratios("after")
        lines.append(f"  held-out RMSE / the prior model's ({g.held_out.rows} samples; below 1: "
                     f"predicts unseen data better): force {fb:.3f} → {fa:.3f}, angular "
                     f"acceleration {tb:.3f} → {ta:.3f}")
    return lines


def _where_lines(diagnosis: Diagnosis) -> list[str]:
    w = diagnosis.where
    lines = []
    if w.windows:
        spans = ", ".join(f"{t0:.1f}–{t1:.1f} s ({AXIS_LABELS[a]}, {z:.1f}× noise)"
                          for t0, t1, a, z in w.windows[:3])
        lines.append(f"  largest in: {spans}")
    else:
        lines.append("  no time window with a residual above twice the noise level")
    if w.worst_regime is not None and w.windows:
        regime, level = w.worst_regime
        lines.append(f"  flight regime where it is largest: {level} {regime.replace('_', ' ')}")
    bad = [AXIS_LABELS[a] for a in range(6) if w.ljung_box_p[a] < 0.01]
    lines.append("  not white (Ljung–Box p < 0.01): " + (", ".join(bad) if bad else "none"))
    b = diagnosis.gap.before
    if b.nis_mean is not None:
        lines.append(f"  EKF NIS (held-out): mean {b.nis_mean:.2f} (6 if consistent), "
                     f"{100 * b.nis_outside:.0f} % outside the χ²(6) 95 % band "
                     f"[{NIS_BAND[0]:.2f}, {NIS_BAND[1]:.1f}] (5 % expected)")
    return lines


def format_diagnosis(diagnosis: Diagnosis, config: VehicleConfig, log_name: str) -> str:
    """The human-readable report of ``mavsysid diagnose``."""
    d = diagnosis
    lines = [f"mavsysid diagnose: {log_name} (vehicle {config.name}, "
             f"{d.t[-1] - d.t[0]:.1f} s; fitted on the first "
             f"{100 * (d.split_time - d.t[0]) / (d.t[-1] - d.t[0]):.0f} %, "
             "checked on the rest)", ""]
    lines.append("Where the model and the measurement disagree "
                 "(accelerations from the smoothed pose vs the model replayed on the logged "
                 "rotor speeds):")
    lines += _where_lines(d)
    lines.append("")
    if not d.effects:
        best = sorted((s for s in d.scores if s.step == 0), key=lambda s: s.delta_bic)
        lines.append("No significant discrepancy: no candidate effect explains the residual "
                     "(none lowers the BIC by more than "
                     f"{10:g}; best {best[0].name}, ΔBIC {best[0].delta_bic:+.1f})."
                     if best else "No significant discrepancy.")
        lines.append("")
        lines += _gap_lines(d)[:1] + _gap_lines(d)[1:]
    else:
        lines.append("Which effect explains it (most important first):")
        lines += _effect_lines(d)
        lines.append("")
        flagged = ", ".join(AXIS_LABELS[a] for a in d.gap.flagged_axes)
        lines.append(f"The gap shrank by {100 * d.gap.shrink:.0f} % on held-out data "
                     f"(last {100 * (1 - (d.split_time - d.t[0]) / (d.t[-1] - d.t[0])):.0f} % "
                     f"of the flight) on the axes the effects act on (*: {flagged}). "
                     "Residual RMS:")
        lines += _gap_lines(d)
        lines.append(f"  BIC (training data): {d.gap.bic_before:.1f} → {d.gap.bic_after:.1f}")
        if d.gap.after.nis_mean is not None and d.gap.before.nis_mean is not None:
            lines.append(f"  EKF NIS mean: {d.gap.before.nis_mean:.2f} → "
                         f"{d.gap.after.nis_mean:.2f}")
        lines.append("")
        lines.append("θ re-fitted to the accelerations without → with the effects:")
        for j, name in enumerate(PARAMETER_NAMES):
            b, a = d.theta_before[j], d.theta_after[j]
            lines.append(f"  {name:4s} {b:12.5g} → {a:12.5g}  ({100 * (a / b - 1):+.2f} %)")
        lines.append("")
        lines.append("Augmented model (add to the vehicle config; `estimate` and `sim` use it):")
        for e in d.augmented_effects:
            lines.append(f"  [effects.{e.name}] " + ", ".join(
                f"{k} = {v:.4g}" for k, v in e.as_dict().items()))
    lines.append("")
    for note in d.notes:
        lines.append(f"Note: {note}.")
    return "\n".join(lines)


def format_reestimate(before: Any, after: Any) -> str:
    """The estimator's θ without and with the named effects (``--reestimate``).

    ``before`` and ``after`` are `EstimationResult` of the model without and with them.
    """
    def final(result: Any) -> Any:
        return result.refined if result.refined is not None else result.filtered

    b, a = final(before), final(after)
    lines = ["", "Re-estimated by the EKF without → with the named effects:"]
    for j, name in enumerate(PARAMETER_NAMES):
        lines.append(f"  {name:4s} {b.value[j]:12.5g} → {a.value[j]:12.5g} ± {a.sigma[j]:.2g}")
    for fe in getattr(after, "effects", ()):
        for j, p in enumerate(fe.effect.parameters):
            sigma = fe.sigma[j]
            lines.append(f"  {fe.effect.name}.{p.name} = {fe.effect.values[j]:.4g} {p.unit}"
                         + (f" ± {sigma:.2g}" if math.isfinite(sigma) else ""))
    truth = after.true_theta
    if truth is not None:
        def err(theta: np.ndarray) -> float:
            return float(np.mean(np.abs(theta / truth - 1.0)))

        lines.append(f"  mean |θ error| against the simulated truth: {100 * err(b.value):.2f} % "
                     f"→ {100 * err(a.value):.2f} %")
    return "\n".join(lines)


def _stats(stats) -> dict:
    return {
        "rms": {a: float(v) for a, v in zip(AXIS_NAMES, stats.rms, strict=True)},
        "ljung_box_p": {a: _num(v) for a, v in zip(AXIS_NAMES, stats.ljung_box_p, strict=True)},
        "nis_mean": _num(stats.nis_mean),
        "nis_outside_band": _num(stats.nis_outside),
    }


def diagnosis_to_json(diagnosis: Diagnosis, config: VehicleConfig, log_name: str) -> dict:
    """docs/architecture.md's diagnose JSON: effects (most important first), ties, gap, where, …"""
    d = diagnosis
    effects = []
    for f in d.effects:
        e = f.effect
        effects.append({
            "name": e.name, "title": e.title, "description": e.description,
            "parameters": {p.name: {"value": float(e.values[j]), "unit": p.unit,
                                    "sigma": float(f.sigma[j]),
                                    "ci95": [float(f.ci95[j, 0]), float(f.ci95[j, 1])]}
                           for j, p in enumerate(e.parameters)},
            "delta_bic": float(f.delta_bic), "p_value": float(f.p_value), "fit": f.kind,
        })
    w = d.where
    return {
        "log": log_name,
        "vehicle": config.name,
        "effects": effects,
        "significant": bool(effects),
        "ties": [{"step": t.step, "chosen": t.chosen, "alternatives": list(t.alternatives),
                  "delta_bic_gap": list(t.delta_bic_gap)} for t in d.ties],
        "gap": {
            "held_out_from_s": float(d.split_time),
            "axis_units": dict(zip(AXIS_NAMES, AXIS_UNITS, strict=True)),
            "before": _stats(d.gap.before), "after": _stats(d.gap.after),
            "flagged_axes": [AXIS_NAMES[a] for a in d.gap.flagged_axes],
            "shrink": float(d.gap.shrink),
            "bic_before": float(d.gap.bic_before), "bic_after": float(d.gap.bic_after),
            "held_out": d.gap.held_out.as_dict() if d.gap.held_out is not None else None,
        },
        "where": {
            "windows": [{"start_s": t0, "end_s": t1, "axis": AXIS_NAMES[a],
                         "normalised_rms": z} for t0, t1, a, z in w.windows],
            "regimes": {k: {"edges": [float(x) for x in v["edges"]],
                            "normalised_rms": [[_num(x) for x in row] for row in v["rms"]]}
                        for k, v in w.regimes.items()},
            "worst_regime": list(w.worst_regime) if w.worst_regime else None,
            "ljung_box_p": {a: _num(v) for a, v in zip(AXIS_NAMES, w.ljung_box_p, strict=True)},
            "noise": {a: float(v) for a, v in zip(AXIS_NAMES, w.noise, strict=True)},
        },
        "candidates": [{"step": s.step, "name": s.name, "delta_bic": float(s.delta_bic),
                        "values": [float(v) for v in s.values]} for s in d.scores],
        "theta": {
            "identified": dict(zip(PARAMETER_NAMES, map(float, d.theta_identified), strict=True)),
            "refit_without_effects": dict(zip(PARAMETER_NAMES, map(float, d.theta_before),
                                              strict=True)),
            "refit_with_effects": dict(zip(PARAMETER_NAMES, map(float, d.theta_after),
                                           strict=True)),
        },
        "augmented_config": vehicle_to_toml(augmented_vehicle(config, d)),
        "mass_check": "not detectable from pose and rotor speeds (docs/architecture.md)",
        "notes": list(d.notes),
    }


def write_diagnosis_json(path: str | Path, diagnosis: Diagnosis, config: VehicleConfig,
                         log_name: str) -> None:
    """Write `diagnosis_to_json` atomically."""
    data = diagnosis_to_json(diagnosis, config, log_name)
    write_json_atomic(path, data)
