"""The paper's repeatability experiment over many experiments: run, store, resume, summarise.

Each finished experiment is stored at once as ``runs/NNNN.json`` in the output folder
(atomically), so an interrupted evaluation keeps what it finished and a second start runs
only the missing experiments. The CSV, the Markdown table and the plots are rebuilt from
the stored records, so they are the same whichever executor ran the experiments:

* ``local``: a process pool on this machine (`concurrent.futures`);
* ``dask``: tasks on an existing ``dask.distributed`` cluster (``--scheduler
  tcp://HOST:8786``); tests use a `LocalCluster` on loopback.

Convergence time follows the paper's Table: per parameter and planner, the first flight
time after which the *median over experiments* of the estimate stays within 5 % of the
truth.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation import (
    CONVERGENCE_TOLERANCE,
    convergence_time,
)
from mavsysid.experiments.experiment import ExperimentSpec, run_experiment
from mavsysid.formats.flight_dir import write_json_atomic
from mavsysid.vehicle.config import PARAMETER_NAMES

from mavsysid.errors import InputError

__all__ = [
    "EvaluationSummary",
    "check_executor",
    "last_flights",
    "load_records",
    "median_convergence_time",
    "paired_flight_arrays",
    "pending_specs",
    "run_specs",
    "summarise",
    "write_csv",
    "write_table",
]

_RUNS = "runs"


def _record_path(out: Path, index: int) -> Path:
    return out / _RUNS / f"{index:04d}.json"


def load_records(out: str | Path) -> list[dict[str, Any]]:
    """Every stored experiment record of an output folder, by index."""
    records = []
    for path in sorted((Path(out) / _RUNS).glob("*.json")):
        try:
            records.append(json.loads(path.read_text(encoding="utf-8")))
        except (OSError, json.JSONDecodeError) as error:
            raise InputError(f"{path}: not a readable experiment record ({error})") from None
    return records


def pending_specs(out: str | Path, specs: Iterable[ExperimentSpec]) -> list[ExperimentSpec]:
    """The specs without a stored record; a record of another spec at the same index is an
    error (the folder belongs to another evaluation)."""
    pending = []
    for spec in specs:
        path = _record_path(Path(out), spec.index)
        if not path.exists():
            pending.append(spec)
            continue
        stored = json.loads(path.read_text(encoding="utf-8")).get("key")
        if stored != spec.key():
            raise InputError(f"{path}: experiment {spec.index} was run with other settings; "
                             "use another --out folder (or delete it) to start afresh")
    return pending


def _local(specs: list[ExperimentSpec], workers: int) -> Iterator[dict[str, Any]]:
    if workers <= 1:
        for spec in specs:
            yield run_experiment(spec)
        return
    with ProcessPoolExecutor(max_workers=workers) as pool:
        running = {pool.submit(run_experiment, spec) for spec in specs}
        while running:
            done, running = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                yield future.result()


def _dask(specs: list[ExperimentSpec], scheduler: str) -> Iterator[dict[str, Any]]:
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise InputError("--executor dask needs dask.distributed: "
                         "pip install 'mavsysid[dask]'") from None
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as error:
        raise InputError(f"--scheduler {scheduler}: cannot reach the Dask scheduler "
                         f"({error})") from None
    with client:
        # pure=False: an experiment is cheap to name but must not be deduplicated by dask.
        futures = client.map(run_experiment, specs, pure=False)
        for future in as_completed(futures):
            yield future.result()


def check_executor(executor: str, scheduler: str | None) -> None:
    """Refuse an unknown executor, or Dask without a scheduler address."""
    if executor not in ("local", "dask"):
        raise InputError(f"--executor {executor!r}: expected 'local' or 'dask'")
    if executor == "dask" and not scheduler:
        raise InputError("--executor dask needs --scheduler tcp://HOST:PORT")


def run_specs(out: str | Path, specs: list[ExperimentSpec], executor: str = "local",
              workers: int = 1, scheduler: str | None = None,
              on_record: Callable[[dict[str, Any]], None] | None = None) -> int:
    """Run the pending experiments of ``specs``, storing each record as it finishes.

    Returns the number of experiments run (0 when everything was already stored).
    """
    out = Path(out)
    check_executor(executor, scheduler)
    todo = pending_specs(out, specs)
    records = _local(todo, workers) if executor == "local" else _dask(todo, scheduler or "")
    count = 0
    for record in records:
        write_json_atomic(_record_path(out, record["spec"]["index"]), record)
        count += 1
        if on_record is not None:
            on_record(record)
    return count


def _rows(records: list[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    for record in records:
        spec = record["spec"]
        for f in record["flights"]:
            row: dict[str, Any] = {"experiment": spec["index"], "seed": spec["seed"],
                                   "kind": f["kind"], "iteration": f["iteration"],
                                   "flight_time": f["flight_time"],
                                   "saturated_fraction": f.get("saturated_fraction", ""),
                                   "tracking_rms": f.get("tracking_rms", ""),
                                   "predicted_dopt": f["predicted_dopt"],
                                   "reached_dopt": f["reached_dopt"]}
            for j, name in enumerate(PARAMETER_NAMES):
                row[f"estimate_{name}"] = f["estimate"][j]
                row[f"relative_sigma_{name}"] = f["relative_sigma"][j]
                row[f"relative_error_{name}"] = f["relative_error"][j]
                conv = f["convergence_time"][j]
                row[f"convergence_time_{name}"] = "" if conv is None else conv
            yield row


def write_csv(path: str | Path, records: list[dict[str, Any]]) -> None:
    """One row per flight (experiment × kind × iteration); numbers with repr precision."""
    rows = list(_rows(records))
    if not rows:
        raise InputError("no finished experiments to write")
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    tmp.replace(path)


def median_convergence_time(t: np.ndarray, ratios: np.ndarray,
                            tolerance: float = CONVERGENCE_TOLERANCE) -> np.ndarray:
    """First time after which the median over experiments stays within the band.

    Parameters
    ----------
    t : ndarray, shape (T,)
        Flight time, s.
    ratios : ndarray, shape (E, T, 6)
        Estimates over truth of E experiments.

    Returns
    -------
    ndarray, shape (6,)
        s; NaN where the median ends outside the band.
    """
    return convergence_time(t, np.median(ratios, axis=0), np.ones(ratios.shape[2]), tolerance)


@dataclass(frozen=True)
class EvaluationSummary:
    """The paper's Table per planner kind (last iteration of each experiment).

    Attributes
    ----------
    kinds : tuple of str
    experiments : int
    convergence_time : dict of str to ndarray, shape (6,)
        Convergence time of the median estimate, s (NaN: never within 5 %).
    median_dopt : dict of str to float
        Median reached D-opt (SI).
    t : ndarray, shape (T,)
        Common flight-time grid of the histories, s.
    ratio_percentiles : dict of str to ndarray, shape (3, T, 6)
        2.5th, 50th and 97.5th percentile of estimate / truth over experiments.
    """

    kinds: tuple[str, ...]
    experiments: int
    convergence_time: dict[str, np.ndarray]
    median_dopt: dict[str, float]
    t: np.ndarray
    ratio_percentiles: dict[str, np.ndarray]


def last_flights(records: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    """Per record that flew ``kind``, its flight of the last iteration."""
    flights = []
    for record in records:
        mine = [f for f in record["flights"] if f["kind"] == kind]
        if mine:
            flights.append(max(mine, key=lambda f: f["iteration"]))
    return flights


def _padded_ratios(flights: list[dict[str, Any]], truth: np.ndarray, length: int
                   ) -> np.ndarray:
    """Estimate / truth on the common grid, shape (E, length, 6); a flight shorter than the
    grid keeps its final estimate (the estimator has no more data)."""
    out = np.empty((len(flights), length, 6))
    for i, f in enumerate(flights):
        theta = np.asarray(f["history"]["theta"], dtype=float)
        out[i, :len(theta)] = theta[:length]
        out[i, len(theta):] = theta[-1]
    return out / truth[:, None, :]


def _history_grid(records: list[dict[str, Any]]) -> np.ndarray:
    longest = max((f["history"]["t"] for r in records for f in r["flights"]), key=len)
    return np.asarray(longest, dtype=float)


def paired_flight_arrays(records: list[dict[str, Any]], kinds: tuple[str, ...]
                         ) -> tuple[np.ndarray, dict[str, np.ndarray],
                                    dict[str, np.ndarray]] | None:
    """Per-experiment arrays of the experiments that flew every one of ``kinds``.

    Returns
    -------
    (t, dopt, ratios) or None
        t : ndarray, shape (T,), the common history grid, s; dopt : kind → reached D-opt,
        shape (E,); ratios : kind → estimate / truth, shape (E, T, 6), row i of every
        kind from the same experiment. None when no experiment flew all ``kinds``.
    """
    both = [r for r in records if set(kinds) <= {f["kind"] for f in r["flights"]}]
    if not both:
        return None
    t = _history_grid(both)
    truth = np.array([r["truth"] for r in both])
    dopt, ratios = {}, {}
    for kind in kinds:
        flights = last_flights(both, kind)
        dopt[kind] = np.array([f["reached_dopt"] for f in flights], dtype=float)
        ratios[kind] = _padded_ratios(flights, truth, t.size)
    return t, dopt, ratios


def summarise(records: list[dict[str, Any]]) -> EvaluationSummary:
    """Aggregate stored records into the paper's Table quantities."""
    if not records:
        raise InputError("no finished experiments to summarise")
    kinds = tuple(dict.fromkeys(f["kind"] for r in records for f in r["flights"]))
    t = _history_grid(records)
    conv, dopt, pct = {}, {}, {}
    for kind in kinds:
        flights = last_flights(records, kind)
        truth = np.array([r["truth"] for r in records
                          if any(f["kind"] == kind for f in r["flights"])])
        ratios = _padded_ratios(flights, truth, t.size)
        conv[kind] = median_convergence_time(t, ratios)
        dopt[kind] = float(np.median([f["reached_dopt"] for f in flights]))
        pct[kind] = np.percentile(ratios, [2.5, 50.0, 97.5], axis=0)
    return EvaluationSummary(kinds, len(records), conv, dopt, t, pct)


_LABELS = {"dopt": "DOPT-COV", "random": "RAND"}


def _seconds(value: float) -> str:
    return "not converged" if math.isnan(value) else f"{value:.2f} s"


def table_markdown(summary: EvaluationSummary) -> str:
    """The paper's Table (CONV TIME per parameter, DOPT) as Markdown."""
    kinds = summary.kinds
    head = "| | parameter | " + " | ".join(_LABELS.get(k, k) for k in kinds) + " |"
    lines = [head, "|---|---|" + "---:|" * len(kinds)]
    for j, name in enumerate(PARAMETER_NAMES):
        label = "CONV TIME" if j == 0 else ""
        cells = " | ".join(_seconds(summary.convergence_time[k][j]) for k in kinds)
        lines.append(f"| {label} | {name} | {cells} |")
    sums = " | ".join(_seconds(float(np.sum(summary.convergence_time[k]))) for k in kinds)
    lines.append(f"| | sum | {sums} |")
    dopts = " | ".join(f"{summary.median_dopt[k]:.3g}" for k in kinds)
    lines.append(f"| DOPT | all | {dopts} |")
    return "\n".join(lines) + "\n"


def write_table(path: str | Path, summary: EvaluationSummary,
                notes: Iterable[str] = ()) -> str:
    """Write the Markdown table with a one-line caption and ``notes`` (one paragraph
    each) under it; returns the table text."""
    text = table_markdown(summary)
    caption = (f"\nConvergence time of the median of the estimates (within "
               f"{CONVERGENCE_TOLERANCE:.0%} of the truth and staying there) and median "
               f"final D-optimality (SI) over {summary.experiments} simulated experiments.\n")
    extra = "".join(f"\n{note}\n" for note in notes)
    Path(path).write_text(text + caption + extra, encoding="utf-8")
    return text
