"""Reading Rerun recordings back in tests, with rerun's own reader."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

__all__ = ["series", "temporal_rows"]


def temporal_rows(path: Path) -> Counter[str]:
    """Number of time points per entity over all its non-static chunks."""
    rows: Counter[str] = Counter()
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            assert chunk.timeline_names == ["time"]
            rows[chunk.entity_path] += chunk.num_rows
    return rows


def series(path: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and scalar values of one entity, in time order."""
    times, values = [], []
    for chunk in RrdReader(path).stream().filter(content=entity, is_static=False):
        batch = chunk.to_record_batch()
        times += [1e-9 * ns for ns in batch.column("time").cast(pa.int64()).to_pylist()]
        values += [v[0] for v in batch.column("Scalars:scalars").to_pylist()]
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], np.asarray(values)[order]
