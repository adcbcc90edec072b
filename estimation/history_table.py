"""The estimate over time as a table and a CSV file (``estimate --history CSV``).

One row per filter step: ``t`` (s, the log's clock), then for each parameter of θ its
filtered value and σ (``c_T, c_T_sigma, c_D, c_D_sigma, …``, SI: the units of
`mavsysid.vehicle.config.PARAMETER_UNITS`), then the normalised innovation squared
``nis``. Floats are written with 17 significant digits, so reading the CSV back gives the
filter's numbers exactly.
"""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
from mavsysid.estimation.results import EstimationHistory
from mavsysid.vehicle.config import PARAMETER_NAMES

__all__ = ["HISTORY_COLUMNS", "history_frame", "write_history_csv"]

#: Columns of the history CSV, in order.
HISTORY_COLUMNS: tuple[str, ...] = (
    "t", *(c for name in PARAMETER_NAMES for c in (name, f"{name}_sigma")), "nis")


def history_frame(history: EstimationHistory) -> pd.DataFrame:
    """The filter's θ and σ over time as a table with `HISTORY_COLUMNS` (N rows)."""
    columns: dict[str, object] = {"t": history.t}
    for j, name in enumerate(PARAMETER_NAMES):
        columns[name] = history.theta[:, j]
        columns[f"{name}_sigma"] = history.theta_sigma[:, j]
    columns["nis"] = history.nis
    return pd.DataFrame(columns, columns=list(HISTORY_COLUMNS))


def write_history_csv(path: str | Path, history: EstimationHistory) -> None:
    """Write `history_frame` as CSV, atomically (a reader never sees half a file).

    Parameters
    ----------
    path : str or Path
        The CSV file; its directory is created.
    history : EstimationHistory
        The filter over time (`mavsysid.estimation.results.EstimationResult.history`).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            history_frame(history).to_csv(f, index=False, float_format="%.17g")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
