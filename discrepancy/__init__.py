"""The model-discrepancy workflow behind ``mavsysid diagnose``.

Put a non-uniformly sampled log on a uniform grid (`resample`), replay the identified
model along the flight (`residuals`), find where it disagrees with the
measurement (`residual_stats`), name the physical effect that explains the gap
(`candidates`, `regression`, `selection`, `selection_model`), fit it through the estimator,
and show the gap shrink on held-out data (`diagnosis`); `mavsysid.pipeline.diagnose` reads
the files and runs it, `report` and `recording` present the result.
"""

__all__: list[str] = []
