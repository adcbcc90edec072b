"""The model-discrepancy workflow behind ``mavsysid diagnose``.

Replay the identified model along a flight (`residuals`), find where it disagrees with the
measurement, name the physical effect that explains the gap (`candidates`, `regression`,
`selection`), fit it through the estimator, and show the gap shrink on held-out data
(`diagnosis`); `report` and `recording` present the result.
"""
