"""``mavsysid diagnose``: find, name and fit what the model still gets wrong.

A thin layer over `run_diagnose` (which tests call directly): read the log (and the
estimate), run `mavsysid.discrepancy.diagnosis.diagnose_flight`, print the report, write the JSON,
the augmented vehicle config and the Rerun recording on request.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mavsysid.discrepancy.diagnosis import (
    MASS_NOTE,
    Diagnosis,
    DiagnosisSettings,
    diagnose_flight,
    reestimate,
)
from mavsysid.discrepancy.report import (
    augmented_vehicle,
    format_diagnosis,
    format_reestimate,
    write_diagnosis_json,
)
from mavsysid.errors import InputError
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.readers import load_flight
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle, save_vehicle
from mavsysid.vehicle.model_effects import ModelEffect, effect_from_values

__all__ = ["DiagnoseRun", "add_arguments", "main", "read_estimate", "run_diagnose"]


@dataclass(frozen=True)
class DiagnoseRun:
    """A finished diagnosis: the vehicle, the flight as read, and the result."""

    config: VehicleConfig
    flight: FlightData
    diagnosis: Diagnosis


def read_estimate(path: str | Path) -> tuple[np.ndarray, tuple[ModelEffect, ...]]:
    """θ (6,) and the model effects of an ``estimate.json`` (docs/architecture.md)."""
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
    """
    config = load_vehicle(vehicle)
    flight = load_flight(log, config)
    theta, known = None, tuple(config.effects)
    if estimate is not None:
        theta, estimated = read_estimate(estimate)
        known = estimated or known
    return DiagnoseRun(config, flight, diagnose_flight(flight, config, theta, settings, known,
                                                       with_nis=with_nis))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``mavsysid diagnose``."""
    parser.add_argument("log", type=Path, help="flight log: pose.csv, .tlog, .ulg or .bin")
    parser.add_argument("--vehicle", default="firefly",
                        help="shipped vehicle name or TOML path (default: firefly)")
    parser.add_argument("--estimate", type=Path, metavar="JSON",
                        help="estimate.json of this flight: the θ to replay (default: the "
                        "vehicle config's)")
    parser.add_argument("-o", "--output", type=Path, metavar="JSON",
                        help="write the diagnosis as JSON")
    parser.add_argument("--write-config", type=Path, metavar="TOML",
                        help="write the vehicle config with the named effects added")
    parser.add_argument("--rrd", type=Path, metavar="FILE",
                        help="write a Rerun recording of the diagnosis")
    parser.add_argument("--holdout", type=float, default=0.3, metavar="FRACTION",
                        help="end of the flight kept out of all fitting (default: 0.3)")
    parser.add_argument("--reestimate", action="store_true",
                        help="also run the estimator (EKF) with the augmented model: θ and "
                        "the effects' parameters estimated together")
    parser.add_argument("--mass-check", action="store_true",
                        help="say whether a wrong mass can be detected, and exit")


def main(args: argparse.Namespace) -> int:
    """Run the command; returns the exit code."""
    if args.mass_check:
        print(f"mass check: {MASS_NOTE}.")
        return 0
    run = run_diagnose(args.log, args.vehicle, args.estimate,
                       DiagnosisSettings(holdout=args.holdout))
    if args.output is not None:
        write_diagnosis_json(args.output, run.diagnosis, run.config, str(args.log))
    if args.write_config is not None:
        save_vehicle(augmented_vehicle(run.config, run.diagnosis), args.write_config)
    if args.rrd is not None:
        from mavsysid.discrepancy.recording import write_diagnosis_rrd  # rerun loads slowly

        write_diagnosis_rrd(args.rrd, run.diagnosis, str(args.log))
    if args.verbosity >= 0:
        print(format_diagnosis(run.diagnosis, run.config, str(args.log)))
    if args.reestimate and run.diagnosis.effects:
        d = run.diagnosis
        known = d.augmented_effects[:len(d.augmented_effects) - len(d.effects)]
        before = reestimate(run.flight, run.config, known)
        after = reestimate(run.flight, run.config, d.augmented_effects)
        if args.verbosity >= 0:
            print(format_reestimate(before, after))
    written = [f"{what} {path}" for what, path in (("diagnosis", args.output),
               ("vehicle", args.write_config), ("recording", args.rrd)) if path is not None]
    if written:
        print("wrote " + ", ".join(written))
    return 0
