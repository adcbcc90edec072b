"""One estimation job: read a flight log and estimate θ (the work of ``mavsysid estimate``).

`run_estimate` is what the command line and the tests call; the console layer
(``mavsysid estimate``) only parses its options, calls it and prints. It reads the log
(`mavsysid.estimation.load_flight`) and answers θ per parameter with
`mavsysid.estimation.estimate`, whose docstring says how.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mavsysid.estimation import (
    EstimationResult,
    EstimatorSettings,
    FilterEstimator,
    FlightData,
    estimate,
    load_flight,
)
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

__all__ = ["EstimateRun", "run_estimate"]


@dataclass(frozen=True)
class EstimateRun:
    """A finished estimation: the vehicle, the flight as read, and the result."""

    config: VehicleConfig
    flight: FlightData
    result: EstimationResult


def run_estimate(
    log: str | Path, vehicle: str | Path = "firefly", pose: str | Path | None = None,
    time_offset: float | None = None, settings: EstimatorSettings | None = None,
    start: float | None = None, end: float | None = None,
    filter_estimate: FilterEstimator | None = None,
) -> EstimateRun:
    """Read a flight log and estimate θ.

    Parameters
    ----------
    log : str or Path
        ``pose.csv``, ``.tlog``, ``.ulg`` or ``.bin``.
    vehicle : str or Path
        Shipped vehicle name or TOML path: known mass and geometry, and the prior.
    pose : str or Path, optional
        External motion-capture pose CSV to merge with the log's rotor speeds.
    time_offset : float, optional
        Clock offset of ``pose`` relative to the log, s (found by cross-correlation
        when not given).
    settings : EstimatorSettings, optional
    start, end : float, optional
        The window of the log to use, s on its clock (default: `load_flight`'s).
    filter_estimate : FilterEstimator, optional
        Estimates θ with the filter (default: the vehicle config's model).

    Returns
    -------
    EstimateRun

    Raises
    ------
    InputError, LogFormatError
        The log or the vehicle file cannot be used (one line).
    JobFailedError
        `mavsysid.estimation.estimate` refuses the flight (one line).
    """
    config = load_vehicle(vehicle)
    flight = load_flight(log, config, pose=pose, time_offset=time_offset, start=start, end=end)
    return EstimateRun(config, flight, estimate(flight, config, settings, filter_estimate))
