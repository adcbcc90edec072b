"""One diagnosis job: read a flight log (and an estimate) and diagnose the model on it.

`run_diagnose` is the work of ``mavsysid diagnose`` (and what tests call directly); the
command itself only parses its options, calls it and prints.

Where the parameter filter could not follow the flight (the estimate's ``filter_refusal``),
or, without ``--estimate``, where θ refitted on the diagnosis' own accelerations is refused,
the θ diagnosed is the force and torque balance's answer (from ``--estimate``'s ``balance``
section, or fitted here by `mavsysid.estimation.balance.fit.fit_wrench_balance`): the
parameters it determines may move with the named effects, the others stay at their prior,
and the residual is taken on derivatives smoothed over the balance's window. Refitting θ on
the diagnosis' own accelerations there lets the noise in logged rotor speeds bias the
inertia (on a real Crazyflie flight, 20× the bifilar value). A refit with the named effects
that is physically impossible is then a note and the balance's θ is kept. Otherwise θ (the
estimate's, or the config's) is refitted, and an impossible one is refused in one line,
before anything is written (`mavsysid.estimation.checks`).
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
from mavsysid.estimation import (
    FlightData,
    check_kinematics,
    check_plausible,
    load_flight,
    report_stage,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from mavsysid.vehicle.model_effects import ModelEffect, effect_from_values

from mavsysid.errors import InputError, JobFailedError

__all__ = ["BalanceStart", "DiagnoseRun", "balance_start", "read_estimate",
           "reestimate_comparison", "run_diagnose"]


@dataclass(frozen=True)
class BalanceStart:
    """Where a diagnosis starts from the force and torque balance's answer.

    Attributes
    ----------
    theta : ndarray, shape (6,)
        The balance's value where it determines a parameter, the prior elsewhere, SI.
    determined : ndarray of bool, shape (6,)
    window : float
        The balance's smoothing window, s.
    source : str
        Where it came from (the estimate file, or "fitted here").
    filter_followed : bool
        Whether the estimate's parameter filter followed the flight (False when the
        balance was fitted here: that is not known without running it).
    """

    theta: np.ndarray
    determined: np.ndarray
    window: float
    source: str
    filter_followed: bool = False


def _balance_from_estimate(path: Path) -> BalanceStart | None:
    """The ``balance`` section of an ``estimate.json``, or None without one."""
    try:
        data = json.loads(path.read_text())
        balance = data.get("balance")
        if not isinstance(balance, dict):
            return None
        params = balance["parameters"]
        theta = np.array([float(params[n]["value"]) for n in PARAMETER_NAMES])
        determined = np.array([params[n]["status"] == "determined" for n in PARAMETER_NAMES])
        window = float(balance["choices"]["window_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not (np.all(np.isfinite(theta)) and math.isfinite(window) and window > 0.0):
        return None
    return BalanceStart(theta, determined, window, str(path),
                        filter_followed=data.get("filter_refusal") is None)


def balance_start(flight: FlightData, config: VehicleConfig,
                  estimate: str | Path | None = None) -> tuple[BalanceStart | None, str | None]:
    """The balance's answer to start the diagnosis from, or None and why there is none.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
        Mass, geometry and the prior θ.
    estimate : str or Path, optional
        An ``estimate.json`` whose ``balance`` section is read (None without one: its θ
        is the start); without an estimate the balance is fitted on ``flight``.
    """
    if estimate is not None:
        found = _balance_from_estimate(Path(estimate))
        if found is None:
            return None, f"{estimate} has no balance section"
        if found.filter_followed:
            return None, None  # the estimate's θ followed the flight: refit from it
        return found, None
    from mavsysid.estimation import (
        fit_wrench_balance,
    )

    report_stage("fitting the force and torque balance")
    try:
        balance = fit_wrench_balance(flight, config)
    except JobFailedError as error:
        return None, str(error).splitlines()[0].removeprefix(f"{flight.source}: ")
    except np.linalg.LinAlgError:
        return None, "the force and torque balance is numerically singular on this flight"
    return BalanceStart(balance.estimate.value.copy(), balance.determined.copy(),
                        float(balance.choices.window), "fitted here"), None


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
        ``estimate.json``: its balance section is the θ to start from, its effects the
        known ones; without a balance section, its θ is refitted. Without an estimate,
        the balance is fitted on the flight.
    settings : DiagnosisSettings, optional
        Its smoother window is replaced by the balance's when θ comes from the balance.
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
        Without a balance answer: the estimate's θ, or θ refitted on the flight, is
        physically impossible or far outside the config's prior (one line naming the file
        and the parameter).
    """
    config = load_vehicle(vehicle)
    theta, known, early = None, tuple(config.effects), []
    if estimate is not None:
        theta, estimated = read_estimate(estimate)
        known = estimated or known
        # The config's own θ is the prior, checked (and warned about) when loaded.
        try:
            check_plausible(str(estimate), theta, None, config.theta, what="identified θ",
                            may_vanish=vanishing_parameters(e.name for e in known),
                            floor=vanishing_floor(known, float(theta[0]),
                                                  config.limits.rotor_speed_max))
        except JobFailedError as error:
            # The balance's answer mixes determined values with prior ones the flight
            # says nothing about: a bound they break together is the prior's to fix.
            if _balance_from_estimate(Path(estimate)) is None:
                raise
            early.append(str(error).splitlines()[0])
    flight = load_flight(log, config, start=start, end=end)
    check_kinematics(flight)  # a clock or position unit the attitude denies
    if estimate is None:
        try:
            return _refitted(flight, config, theta, settings, known, with_nis, None)
        except JobFailedError:
            # The model does not follow this flight on its own accelerations: start from
            # the force and torque balance instead, if the flight determines anything.
            start_from, why_not = balance_start(flight, config, None)
            if start_from is None:
                raise
    else:
        start_from, why_not = balance_start(flight, config, estimate)
        if start_from is None:
            return _refitted(flight, config, theta, settings, known, with_nis, why_not)
    return DiagnoseRun(config, flight, _from_balance(flight, config, start_from, settings,
                                                     known, with_nis, early))


def _refitted(flight: FlightData, config: VehicleConfig, theta: np.ndarray | None,
              settings: DiagnosisSettings | None, known: tuple[ModelEffect, ...],
              with_nis: bool, why_not: str | None) -> DiagnoseRun:
    """The diagnosis that refits θ on its own accelerations; an impossible refit refused."""
    diagnosis = diagnose_flight(flight, config, theta, settings, known, with_nis=with_nis)
    notes = (*check_refits(flight.source, diagnosis, config),
             *((f"θ refitted on the diagnosis' accelerations: no force and torque "
                f"balance answer ({why_not})",) if why_not else ()))
    return DiagnoseRun(config, flight, replace(diagnosis, notes=(*diagnosis.notes, *notes)))


def _from_balance(flight: FlightData, config: VehicleConfig, start_from: BalanceStart,
                  settings: DiagnosisSettings | None, known: tuple[ModelEffect, ...],
                  with_nis: bool, early: list[str]) -> Diagnosis:
    """The diagnosis from the balance's θ (module docstring), with its notes."""
    settings = settings or DiagnosisSettings()
    settings = replace(settings, smoother=replace(settings.smoother, window=start_from.window))
    # The NIS needs the parameter filter (a minute on 50 s at 500 Hz): run only where
    # the estimate says it follows the flight.
    nis = with_nis and start_from.filter_followed
    diagnosis = diagnose_flight(flight, config, start_from.theta, settings, known,
                                with_nis=nis, free_theta=start_from.determined)
    held = [n for n, d in zip(PARAMETER_NAMES, start_from.determined, strict=True) if not d]
    notes = [f"θ from the force and torque balance ({start_from.source}; smoother "
             f"{1e3 * start_from.window:.0f} ms)"
             + (f"; {', '.join(held)} not determined by this flight, held at the prior"
                if held else ""), *early]
    if with_nis and not nis:
        notes.append("no EKF NIS: " + ("the estimate's parameter filter could not follow "
                     "this flight" if start_from.source != "fitted here" else
                     "run `mavsysid estimate` and pass its --estimate for it"))
    try:
        # θ before the effects is the balance's own, judged above: only the refit counts.
        notes += [n for n in check_refits(flight.source, diagnosis, config)
                  if not n.startswith("θ refitted without")]
    except JobFailedError as error:
        reason = str(error).splitlines()[0].removeprefix(f"{flight.source}: ")
        notes.append(f"{reason}; the balance's θ is kept")
        diagnosis = replace(diagnosis, theta_after=diagnosis.theta_before.copy(),
                            theta_after_sigma=None)
    return replace(diagnosis, notes=(*diagnosis.notes, *notes))


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
