"""One diagnosis job: read a flight log (and an estimate) and diagnose the model on it.

`run_diagnose` is the work of ``mavsysid diagnose`` (and what tests call directly); the
command itself only parses its options, calls it and prints. A θ it would replay or report
that is physically impossible or far outside the prior (`mavsysid.estimation.plausibility`)
is refused in one line, before anything is written.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.discrepancy.diagnosis import (
    Diagnosis,
    DiagnosisSettings,
    check_refits,
    diagnose_flight,
    reestimate,
)
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.plausibility import (
    check_plausible,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.tilt_consistency import check_kinematics
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from mavsysid.vehicle.model_effects import ModelEffect, effect_from_values

from mavsysid.errors import InputError

__all__ = ["DiagnoseRun", "read_estimate", "reestimate_comparison", "run_diagnose"]


@dataclass(frozen=True)
class DiagnoseRun:
    """A finished diagnosis: the vehicle, the flight as read, and the result."""

    config: VehicleConfig
    flight: FlightData
    diagnosis: Diagnosis


def read_estimate(path: str | Path) -> tuple[np.ndarray, tuple[ModelEffect, ...]]:
    """θ (6,) and the model effects of an ``estimate.json`` (docs/architecture.md).

    Parameters
    ----------
    path : str or Path
        The ``estimate.json`` file.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        params = data["parameters"]
        theta = np.array([float(params[n]["value"]) for n in PARAMETER_NAMES])
        effects = tuple(
            effect_from_values(e["name"], {k: float(v["value"]) for k, v in
                                           e.get("parameters", {}).items()})
            for e in data.get("effects", []) or [])
    except FileNotFoundError:
        raise InputError(f"{path}: no such estimate file") from None
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise InputError(f"{path}: not a readable estimate.json ({type(error).__name__}: "
                         f"{error})") from None
    if not all(math.isfinite(v) for v in theta):
        raise InputError(f"{path}: θ has a missing or non-finite value")
    return theta, effects


def run_diagnose(
    log: str | Path, vehicle: str | Path = "firefly", estimate: str | Path | None = None,
    settings: DiagnosisSettings | None = None, with_nis: bool = True,
    start: float | None = None, end: float | None = None,
) -> DiagnoseRun:
    """Read a flight log (and an estimate) and diagnose the model on it.

    Parameters
    ----------
    log : str or Path
        ``pose.csv``, ``.tlog``, ``.ulg`` or ``.bin``.
    vehicle : str or Path
        Shipped vehicle name or TOML path; its ``[effects.*]`` are the known effects.
    estimate : str or Path, optional
        ``estimate.json``: θ (and effects) to replay; the config's θ otherwise.
    settings : DiagnosisSettings, optional
    with_nis : bool
        Also run the parameter EKF for its NIS.
    start, end : float, optional
        The window of the log to use, s on its clock (default: `load_flight`'s).

    Returns
    -------
    DiagnoseRun

    Raises
    ------
    JobFailedError
        The estimate's θ, or θ refitted on the flight, is physically impossible or far
        outside the config's prior (one line naming the file and the parameter).
    """
    config = load_vehicle(vehicle)
    theta, known = None, tuple(config.effects)
    if estimate is not None:
        theta, estimated = read_estimate(estimate)
        known = estimated or known
        # The config's own θ is the prior, checked (and warned about) when loaded.
        check_plausible(str(estimate), theta, None, config.theta, what="identified θ",
                        may_vanish=vanishing_parameters(e.name for e in known),
                        floor=vanishing_floor(known, float(theta[0]),
                                              config.limits.rotor_speed_max))
    flight = load_flight(log, config, start=start, end=end)
    check_kinematics(flight)  # a clock or position unit the attitude denies
    diagnosis = diagnose_flight(flight, config, theta, settings, known, with_nis=with_nis)
    notes = check_refits(flight.source, diagnosis, config)
    diagnosis = replace(diagnosis, notes=(*diagnosis.notes, *notes))
    return DiagnoseRun(config, flight, diagnosis)


def reestimate_comparison(run: DiagnoseRun) -> tuple[Any, Any]:
    """The estimator (EKF) run with the known effects only, and with the augmented model.

    Parameters
    ----------
    run : DiagnoseRun
        A diagnosis with its flight and config.

    Returns
    -------
    before, after : EstimationResult
        θ and the effects' parameters estimated together without and with the named
        effects (see `mavsysid.discrepancy.diagnosis.reestimate`).
    """
    d = run.diagnosis
    known = d.augmented_effects[:len(d.augmented_effects) - len(d.effects)]
    before = reestimate(run.flight, run.config, known)
    after = reestimate(run.flight, run.config, d.augmented_effects)
    return before, after
