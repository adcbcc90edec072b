"""The per-flight table and the summary of `bench/crazyflie_flights.py`."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["TARGETS", "markdown_table", "print_summary", "print_table", "summary"]

#: Acceptance bounds on |error| against the reference: c_T 10 %, j_x and j_y 25 %.
TARGETS = {"c_T": 0.10, "j_x": 0.25, "j_y": 0.25}
#: The stand reference's own relative σ (±3 % of the least-squares stand fit; the two
#: brushed stand files differ by 6 %), for the coverage that allows for it.
REFERENCE_SIGMA = {"c_T": 0.03}


def _cell(balance: dict, k: int) -> str:
    """One parameter: error ± relative σ, status, coverage (or the value without reference)."""
    value, err = balance["data"]["value"][k], balance["data"]["error"][k]
    sigma = balance["data"]["sigma"][k]
    rel = abs(sigma / value) if value else float("inf")
    rel_text = f"{100 * rel:.0f}" if rel < 10 else ">999"
    determined = balance["status"][k] == "determined"
    if err is None:
        body = f"{value:.3g}±{rel_text}%"
    else:
        body = f"{100 * err:+.0f}±{rel_text}%"
        if determined:
            body += " ok" if balance["covered"][k] else " OUT"
    return ("D " if determined else "- ") + body


def print_table(rows: Sequence[dict], names: Sequence[str]) -> None:
    """Per flight: duration, band, offset, each parameter, held-out ratio, run times, tool."""
    head = (f"{'flight':9s} {'dur':>5s} {'band Hz':>9s} {'δ ms':>5s} "
            + " ".join(f"{n:>15s}" for n in names)
            + f" {'held-out':>9s} {'t s':>5s}  estimate today")
    print(head)
    for row in rows:
        name = row["flight"]
        if "skipped" in row:
            said = row.get("tool", {})
            print(f"{name:9s} skipped: {row['skipped']}"
                  + (f"; estimate exit {said['code']}: {said['message']}" if said else ""))
            continue
        b = row["balance"]
        line = f"{name:9s} {row['duration']:5.1f} "
        if b.get("reader_refusal"):
            print(f"{name:9s} the reader refuses the log ({b['reader_refusal']}); the balance "
                  "on the log as written:")
        if b["code"]:
            line += f"REFUSED exit {b['code']}: {b['message']}"
        else:
            band = b["roll_pitch_band"]
            band_text = f"{band[0]:.1f}-{band[1]:.1f}" if band else "none"
            ho = b["holdout"] or {}
            ho_text = "/".join("-" if ho.get(k) is None else f"{ho[k]:.2f}"
                               for k in ("force_ratio", "torque_ratio"))
            line += (f"{band_text:>9s} {1000 * b['delay_s']:+5.1f} "
                     + " ".join(f"{_cell(b, k):>15s}" for k in range(len(names)))
                     + f" {ho_text:>9s} {b['seconds']:5.1f}")
        tool = row.get("tool")
        if tool is not None:
            if tool["code"]:
                line += f"  exit {tool['code']} ({tool['seconds']:.0f} s)"
            else:
                err = tool["error"][0]
                line += f"  exit 0, c_T {100 * err:+.1f} % ({tool['seconds']:.0f} s)"
        print(line)


def summary(rows: Sequence[dict]) -> dict:
    """Counts and figures over the flights (see `print_summary`)."""
    with_data = [r for r in rows if "skipped" not in r]
    answered = [r for r in with_data if r["balance"]["code"] == 0]
    out = {"flights": len(rows), "with_data": len(with_data), "answered": len(answered),
           "refused": [(r["flight"], r["balance"]["message"]) for r in with_data
                       if r["balance"]["code"]], "parameters": {}}
    names = ("c_T", "c_D", "c_M", "j_x", "j_y", "j_z")
    for k, name in enumerate(names):
        det = [r for r in answered if r["balance"]["status"][k] == "determined"]
        errors = [r["balance"]["data"]["error"][k] for r in det]
        entry = {"determined": len(det),
                 "covered": sum(bool(r["balance"]["covered"][k]) for r in det
                                if r["balance"]["covered"][k] is not None)}
        if name in REFERENCE_SIGMA and det and errors[0] is not None:
            entry["covered_with_reference_sigma"] = sum(
                abs(r["balance"]["data"]["error"][k]) <= 1.96 * np.hypot(
                    REFERENCE_SIGMA[name],
                    r["balance"]["data"]["sigma"][k] / r["balance"]["data"]["value"][k])
                for r in det)
        if name in TARGETS and errors and errors[0] is not None:
            entry["within_target"] = sum(abs(e) <= TARGETS[name] for e in errors)
        all_err = [r["balance"]["data"]["error"][k] for r in answered]
        if all_err and all_err[0] is not None:
            entry["median_abs_error_all"] = float(np.nanmedian(np.abs(np.array(
                [np.nan if e is None else e for e in all_err], float))))
        out["parameters"][name] = entry
    for key in ("ratio", "force_ratio", "torque_ratio"):
        ratios = [r["balance"]["holdout"][key] for r in answered if r["balance"]["holdout"]]
        ratios = [x for x in ratios if x is not None]
        if ratios:
            out[f"holdout_{key}"] = {
                "median": float(np.median(ratios)), "min": float(min(ratios)),
                "max": float(max(ratios)), "below_1": sum(x < 1 for x in ratios),
                "n": len(ratios)}
    tools = [r["tool"] for r in with_data if "tool" in r]
    if tools:
        codes = [t["code"] for t in tools]
        out["tool"] = {str(c): codes.count(c) for c in sorted(set(codes))}
    return out


def _spread(rows: Sequence[dict], vehicle: str, k: int) -> tuple[int, float, float]:
    """Determined values of one parameter on one vehicle: count, relative SD, RMS rel. σ."""
    vals, sig = [], []
    for r in rows:
        b = r.get("balance", {})
        if r.get("vehicle") == vehicle and b.get("code") == 0 \
                and b["status"][k] == "determined":
            vals.append(b["data"]["value"][k])
            sig.append(b["data"]["sigma"][k])
    if len(vals) < 3:
        return len(vals), float("nan"), float("nan")
    vals, sig = np.array(vals), np.array(sig)
    mean = float(np.mean(vals))
    return len(vals), float(np.std(vals, ddof=1) / mean), float(np.sqrt(np.mean(sig**2)) / mean)


def print_summary(rows: Sequence[dict], references: dict) -> None:
    """Acceptance counts, held-out ratios, and σ against the spread across flights."""
    s = summary(rows)
    print(f"\n{s['flights']} flights, {s['with_data']} with data, {s['answered']} answered "
          f"(≥ 1 parameter determined), {len(s['refused'])} refused")
    for name, entry in s["parameters"].items():
        print(f"  {name:4s} {entry}")
    for key in ("ratio", "force_ratio", "torque_ratio"):
        if f"holdout_{key}" in s:
            print(f"  held-out RMSE {key} to the prior: {s[f'holdout_{key}']}")
    if "tool" in s:
        print(f"  today's estimate, exit codes: {s['tool']}")
    print("  spread across flights vs reported σ (determined values):")
    for vehicle in references:
        for k, name in enumerate(("c_T", "c_D", "c_M", "j_x", "j_y", "j_z")):
            n, sd, sig = _spread(rows, vehicle, k)
            if n >= 3:
                print(f"    {vehicle:9s} {name:4s} n={n:2d}  SD {100 * sd:5.1f} %  "
                      f"RMS σ {100 * sig:5.1f} %")


def _md_cell(balance: dict, k: int) -> str:
    value, err = balance["data"]["value"][k], balance["data"]["error"][k]
    rel = abs(balance["data"]["sigma"][k] / value) if value else float("inf")
    if balance["status"][k] != "determined":
        return "–"
    text = f"{value:.3g} ±{100 * rel:.0f} %" if err is None else \
        f"{100 * err:+.1f} ±{100 * rel:.1f} %"
    if err is not None:
        text += "" if balance["covered"][k] else " ✗"
    return text


def markdown_table(rows: Sequence[dict]) -> str:
    """Per flight, as a Markdown table: the determined parameters (error ± σ, ✗ = the
    reference outside the 95 % interval; – = not determined), band, offset, held-out
    force/torque ratios and the `estimate` exit code."""
    head = ("| flight | s | band Hz | δ ms | c_T | c_D | j_x | j_y | j_z | c_M/j_z | "
            "held-out F/M | `estimate` |\n|" + "---|" * 12)
    lines = [head]
    for row in rows:
        tool = row.get("tool")
        tool_text = "" if tool is None else f"exit {tool['code']}" + (
            f", c_T {100 * tool['error'][0]:+.0f} %" if tool["code"] == 0 else "")
        if "skipped" in row:
            lines.append(f"| {row['flight']} | | {row['skipped']} |" + " |" * 9)
            continue
        b = row["balance"]
        if tool is None:  # the row is `estimate`'s own
            tool_text = f"exit {b['code']}" + (", filter refused" if b.get("filter_refusal")
                                               else "")
        if b["code"]:
            reason = b["message"].split(": ", 1)[-1].split(";")[0].split(" while ")[0]
            lines.append(f"| {row['flight']} | {row['duration']:.1f} | refused (exit "
                         f"{b['code']}): {reason} |" + " |" * 8 + f" {tool_text} |")
            continue
        band = b["roll_pitch_band"]
        band_text = f"{band[0]:.1f}–{band[1]:.1f}" if band else "none"
        ho = b["holdout"] or {}
        ho_text = "/".join("–" if ho.get(k) is None else f"{ho[k]:.2f}"
                           for k in ("force_ratio", "torque_ratio"))
        ratio = b["combinations"][0]
        ratio_sigma = b["combination_sigma"][0]
        ratio_text = f"{ratio:.2e} ±{100 * ratio_sigma / abs(ratio):.0f} %" \
            if ratio and np.isfinite(ratio_sigma) and ratio_sigma < abs(ratio) else "–"
        cells = [_md_cell(b, k) for k in (0, 1, 3, 4, 5)]
        lines.append(f"| {row['flight']}{' ¹' if b.get('reader_refusal') else ''} | "
                     f"{row['duration']:.1f} | {band_text} | {1000 * b['delay_s']:+.1f} | "
                     + " | ".join(cells) + f" | {ratio_text} | {ho_text} | {tool_text} |")
    return "\n".join(lines) + "\n"
