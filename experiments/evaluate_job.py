"""One evaluation job: the paper's repeatability experiment (the work of ``mavsysid evaluate``).

`make_specs` builds the experiments' specs and `run_evaluation` runs what is missing and
writes ``runs.csv``, ``table.md``, the plots and the recording; the console layer
(``mavsysid evaluate``) only parses its options, calls them and prints.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

from mavsysid.experiments.evaluation import (
    EvaluationSummary,
    check_executor,
    load_records,
    pending_specs,
    run_specs,
    summarise,
    write_csv,
    write_table,
)
from mavsysid.experiments.evaluation_intervals import (
    OFF_PATH_RMS,
    SATURATED_SHARE,
    HeadlineFigures,
    headline_intervals,
    off_path_flights,
    saturating_flights,
)
from mavsysid.experiments.experiment import KINDS, ExperimentSpec, controller_config
from mavsysid.planner.feasibility import check_rotor_headroom
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle
from tqdm import tqdm

from mavsysid.errors import InputError

__all__ = ["EvaluationRun", "make_specs", "run_evaluation", "table_notes"]

#: What the notes call each kind of experiment.
_KIND_NAMES = {"dopt": "planned", "random": "random"}


@dataclass(frozen=True)
class EvaluationRun:
    """A finished evaluation: where it is, what ran now, and the summary."""

    out: Path
    ran: int
    summary: EvaluationSummary
    table: str
    files: dict[str, Path]
    headline: HeadlineFigures | None = None
    saturating: dict[str, tuple[int, int]] | None = None
    off_path: dict[str, tuple[int, int]] | None = None


def make_specs(n: int, vehicle: str = "firefly", budget: float = 30.0,
               planning_time: float = 30.0, samples: int | None = None,
               box: tuple[float, ...] = PlannerSettings.box, seed: int = 0,
               iterations: int = 1, refine_steps: int | None = None,
               rotor_headroom: float = PlannerSettings.rotor_headroom,
               controller_model: str = "truth") -> list[ExperimentSpec]:
    """The specs of experiments 0 … n−1 (experiment i uses seed ``seed + i``)."""
    if n < 1:
        raise InputError(f"--n {n}: expected at least 1 experiment")
    if iterations < 1:
        raise InputError(f"--iterations {iterations}: expected at least 1")
    if samples is not None and samples < 1:
        raise InputError(f"--samples {samples}: expected at least 1")
    if not budget > 0.0:
        raise InputError(f"--budget {budget:g}: expected > 0 s")
    if samples is None and not (planning_time > 0.0 and math.isfinite(planning_time)):
        raise InputError(f"--time {planning_time:g}: expected a finite planning time > 0 s "
                         "(or --samples N)")
    # A bad vehicle, headroom or controller model fails here, not inside a worker.
    truth = load_vehicle(vehicle)
    check_rotor_headroom(truth, rotor_headroom, "--rotor-headroom")
    controller_config(controller_model, truth, truth)
    return [ExperimentSpec(index=i, seed=seed + i, vehicle=str(vehicle), budget=budget,
                           planning_time=planning_time, samples=samples,
                           box=tuple(box), iterations=iterations, kinds=KINDS,  # type: ignore[arg-type]
                           refine_steps=refine_steps, rotor_headroom=rotor_headroom,
                           controller_model=controller_model)
            for i in range(n)]


def run_evaluation(out: str | Path, specs: list[ExperimentSpec], executor: str = "local",
                   workers: int = 1, scheduler: str | None = None, rrd: Path | None = None,
                   png: bool = True, progress: bool = False) -> EvaluationRun:
    """Run what is missing, then write runs.csv, table.md, the plots and the recording."""
    out = Path(out)
    check_executor(executor, scheduler)
    done_before = len(specs) - len(pending_specs(out, specs))  # refuses a foreign folder
    out.mkdir(parents=True, exist_ok=True)
    bar = tqdm(total=len(specs), initial=done_before, unit="experiment", file=sys.stderr,
               disable=not progress, desc="evaluate")
    with bar:
        ran = run_specs(out, specs, executor, workers, scheduler,
                        on_record=lambda _record: bar.update(1))
    wanted = {s.index for s in specs}
    records = [r for r in load_records(out) if r["spec"]["index"] in wanted]
    files = {"csv": out / "runs.csv", "table": out / "table.md"}
    write_csv(files["csv"], records)
    summary = summarise(records)
    headline = headline_intervals(records)
    saturating, off_path = saturating_flights(records), off_path_flights(records)
    table = write_table(files["table"], summary, notes=table_notes(headline, saturating, off_path))
    if png:
        from mavsysid.experiments.evaluation_plots import write_evaluation_pngs

        convergence, errors = write_evaluation_pngs(out, summary, records)
        files.update({"convergence plot": convergence, "error plot": errors})
    if rrd is not None:
        from mavsysid.experiments.evaluation_plots import write_evaluation_rrd

        write_evaluation_rrd(rrd, summary)
        files["recording"] = Path(rrd)
    return EvaluationRun(out, ran, summary, table, files, headline, saturating, off_path)


def table_notes(headline: HeadlineFigures | None, saturating: dict[str, tuple[int, int]],
                off_path: dict[str, tuple[int, int]]) -> list[str]:
    """Lines under the table (table.md and the command's output): the headline figures'
    intervals, and the flights that saturated a rotor or left their path."""
    notes = []
    if headline is not None:
        level = f"{100 * headline.confidence:.0f} %"
        d_lo, d_hi = headline.dopt_ratio_interval
        c_lo, c_hi = headline.convergence_reduction_interval
        notes.append(
            f"Median D-opt random / planned {headline.dopt_ratio:.2f} ({level} paired "
            f"bootstrap interval over the {headline.experiments} experiments "
            f"{d_lo:.2f}–{d_hi:.2f}; paper: 4.4); summed convergence time "
            f"{100 * headline.convergence_reduction:.0f} % less with the planner "
            f"({100 * c_lo:.0f}–{100 * c_hi:.0f} %; paper: 65 %; a parameter that never "
            "settles counts as the whole flight).")
    if saturating:
        notes.append(f"Flights saturating a rotor on more than {100 * SATURATED_SHARE:g} % of "
                     f"the control ticks: "
                     f"{_flight_counts(saturating)}.")
    if off_path:
        notes.append(f"Flights off their path by more than {OFF_PATH_RMS:g} m RMS (the true "
                     f"vehicle could not fly the plan): {_flight_counts(off_path)}.")
    return notes


def _flight_counts(counts: dict[str, tuple[int, int]]) -> str:
    """``planned 2 of 20, random 5 of 20``: flights counted per kind of experiment."""
    return ", ".join(f"{_KIND_NAMES.get(k, k)} {n} of {total}" for k, (n, total) in counts.items())

