"""One repeatability experiment of the paper's evaluation (Section "Simulation Based
Experiments"), and the iterative identification the paper names as future work.

An experiment draws the unknown parameters ±50 % around the truth; that draw is the
planner's model and the EKF's initial guess. For each planner kind (the D-optimal planner
and the random baseline) it plans a flight within the budget, flies it in the offline
simulator with the true θ (the flight controller tuned to the true vehicle, as RotorS's is
in the paper and a real autopilot is after tuning; or, with ``controller_model="prior"``,
to the guess), runs the paper's EKF on
the pose log and keeps what the evaluation reports: final σ, relative error, D-opt,
per-parameter convergence time and the estimate over flight time. With ``iterations > 1``
the flight is planned again with the updated model and flown again; the filter of each
iteration starts from the previous iteration's estimate and covariance.

`run_experiment` is a pure function of its `ExperimentSpec` (every random choice is
seeded by it), so any executor — a local process pool or a Dask cluster — gives the same
record for the same spec.
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation import (
    ParameterEKF,
    ParameterEstimate,
    convergence_time,
    load_flight,
)
from mavsysid.experiments.data_efficiency import seconds_to_relative_sigma
from mavsysid.flight.offline.simulator import SimulationResult, SimulationSettings, Simulator
from mavsysid.planner.baseline import plan_random
from mavsysid.planner.plan_result import PlanResult
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.linearization import initial_state_sigma

from mavsysid.errors import InputError

__all__ = ["CONTROLLER_MODELS", "KINDS", "ExperimentSpec", "controller_config", "draw_prior",
           "estimate_history", "filter_flight", "fly_plan", "run_experiment"]

#: Planner kinds, in the paper's names: DOPT-COV (ours) and RAND.
KINDS: tuple[str, ...] = ("dopt", "random")
#: Rate at which estimate histories are kept in a record, Hz.
HISTORY_RATE = 10.0
#: Relative half-width of the draw of the unknown parameters around the truth.
PRIOR_SPREAD = 0.5
#: Which θ the simulated flight controller is tuned with.
CONTROLLER_MODELS: tuple[str, ...] = ("truth", "prior")


@dataclass(frozen=True)
class ExperimentSpec:
    """Everything that determines one experiment.

    Attributes
    ----------
    index : int
        Position in the evaluation (0-based); also the default seed offset.
    seed : int
        Seed of the parameter draw, the planners and the simulator.
    vehicle : str
        Shipped vehicle name or TOML path (the truth).
    budget : float
        Flight-time budget, s.
    planning_time : float
        Planning time per plan, s (inf with a sample budget).
    samples : int or None
        Planner sample budget; makes the record independent of machine and load.
    box : tuple of 6 float
        Flight box, m, world ENU.
    iterations : int
        Plan–fly–estimate rounds (1: the paper's experiment).
    kinds : tuple of str
        Planner kinds to run.
    refine_steps : int or None
        Most refinement steps of the D-optimal planner (None: the planner's default).
    rotor_headroom : float
        The planners' rotor headroom (`mavsysid.planner.settings.PlannerSettings.rotor_headroom`).
    controller_model : {"truth", "prior"}
        θ of the simulated flight controller's model: the truth (the paper's RotorS
        controller; a tuned autopilot) or the model the flight was planned with.
    """

    index: int
    seed: int
    vehicle: str = "firefly"
    budget: float = 30.0
    planning_time: float = 30.0
    samples: int | None = None
    box: tuple[float, float, float, float, float, float] = PlannerSettings.box
    iterations: int = 1
    kinds: tuple[str, ...] = KINDS
    refine_steps: int | None = None
    rotor_headroom: float = PlannerSettings.rotor_headroom
    controller_model: str = "truth"

    def key(self) -> str:
        """A short hash of the spec: a stored record is reused only for the same spec."""
        text = json.dumps(asdict(self), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def controller_config(name: str, truth: VehicleConfig, guess: VehicleConfig) -> VehicleConfig:
    """The vehicle model the simulated flight controller is tuned with.

    ``"truth"``: the true vehicle (the paper's RotorS controller, a tuned autopilot);
    ``"prior"``: the model the flight was planned with. Anything else is an InputError
    naming ``--controller-model``.
    """
    if name not in CONTROLLER_MODELS:
        raise InputError(f"--controller-model {name!r}: expected one of "
                         f"{', '.join(CONTROLLER_MODELS)}")
    return truth if name == "truth" else guess


def draw_prior(truth: VehicleConfig, seed: int) -> np.ndarray:
    """The unknown parameters drawn uniformly ±50 % around the truth, shape (6,)."""
    rng = np.random.default_rng([seed, 20_000])
    return truth.theta * (1.0 + rng.uniform(-PRIOR_SPREAD, PRIOR_SPREAD, 6))


def _planner_settings(spec: ExperimentSpec, seed: int) -> PlannerSettings:
    time = math.inf if spec.samples is not None else spec.planning_time
    settings = PlannerSettings(budget=spec.budget, planning_time=time,
                               max_samples=spec.samples, box=spec.box, seed=seed,
                               rotor_headroom=spec.rotor_headroom)
    if spec.refine_steps is not None:
        settings = replace(settings, refine_steps=spec.refine_steps)
    return settings


def filter_flight(directory: Path, model: VehicleConfig, prior: ParameterEstimate):
    """The paper's EKF over a simulated flight's pose log, from an explicit prior."""
    flight = load_flight(directory / "pose.csv", model)
    sigma = (model.noise.position_sigma, model.noise.attitude_sigma)
    state_sigma = initial_state_sigma(sigma[0], sigma[1], float(flight.t[1] - flight.t[0]))
    return ParameterEKF(model, prior, sigma).run(flight, state_sigma)


def estimate_history(t: np.ndarray, theta: np.ndarray, sigma: np.ndarray
                     ) -> dict[str, list]:
    """The estimate over flight time resampled at `HISTORY_RATE` (for medians and plots)."""
    grid = np.arange(0.0, t[-1] - t[0] + 1e-9, 1.0 / HISTORY_RATE)
    tt = t - t[0]
    th = np.column_stack([np.interp(grid, tt, theta[:, j]) for j in range(6)])
    sg = np.column_stack([np.interp(grid, tt, sigma[:, j]) for j in range(6)])
    return {"t": grid.round(6).tolist(), "theta": th.tolist(), "sigma": sg.tolist()}


def fly_plan(spec: ExperimentSpec, truth: VehicleConfig, model: VehicleConfig, kind: str,
             iteration: int, directory: Path) -> tuple[PlanResult, SimulationResult]:
    """Plan one flight of an experiment with ``model`` and fly it with the truth.

    The pose log goes to ``directory``; the seed depends only on the spec and the
    iteration, so the flight is the same wherever and whenever it runs.
    """
    seed = spec.seed * 100 + iteration
    planner = plan if kind == "dopt" else plan_random
    result = planner(model, _planner_settings(spec, seed))
    controlled = controller_config(spec.controller_model, truth, model)
    sim = Simulator(controlled, true_theta=truth.theta,
                    settings=SimulationSettings(seed=seed)).run(result.trajectory, directory)
    return result, sim


def _seconds_or_none(value: float) -> float | None:
    return None if math.isnan(value) else float(value)


def _fly(spec: ExperimentSpec, truth: VehicleConfig, model: VehicleConfig,
         prior: ParameterEstimate, kind: str, iteration: int, workdir: Path) -> dict[str, Any]:
    """Plan with ``model``, fly with the truth, filter from ``prior``: one record row."""
    directory = workdir / f"{kind}-{iteration}"
    result, sim = fly_plan(spec, truth, model, kind, iteration, directory)
    run = filter_flight(directory, model, prior)
    est = run.estimate
    h = run.history
    return {
        "kind": kind,
        "iteration": iteration,
        "flight_time": float(result.trajectory.duration),
        # The true vehicle may need rotor speeds the plan's prior did not: then it
        # saturates and leaves the planned path.
        "saturated_fraction": float(sim.saturated_fraction),
        "tracking_rms": float(sim.position_rms),
        "predicted_dopt": float(result.predicted_dopt),
        "reached_dopt": est.d_optimality,
        "estimate": est.value.tolist(),
        "covariance": est.covariance.tolist(),
        "relative_sigma": (est.sigma / truth.theta).tolist(),
        "relative_error": ((est.value - truth.theta) / truth.theta).tolist(),
        "convergence_time": [None if math.isnan(v) else float(v) for v in
                             convergence_time(h.t - h.t[0], h.theta, truth.theta)],
        # The data-efficiency endpoint (`mavsysid.experiments.data_efficiency`); None
        # when some σ_j/θ_j stays above 1 % to the end of the flight.
        "time_to_relative_sigma": _seconds_or_none(seconds_to_relative_sigma(
            h.t - h.t[0], h.theta_sigma, truth.theta)),
        "planner": {"samples": result.stats.samples, "vertices": result.stats.vertices,
                    "edges": result.stats.edges},
        "history": estimate_history(h.t, h.theta, h.theta_sigma),
        "_estimate": est,
    }


def run_experiment(spec: ExperimentSpec) -> dict[str, Any]:
    """Run one experiment; returns its JSON-ready record.

    Returns
    -------
    dict
        ``{"spec": .., "key": .., "truth": θ, "prior": θ₀, "flights": [row, ...]}`` with
        one row per (kind, iteration); see `_fly` for the row's fields (SI; relative σ
        and errors are relative to the true θ; convergence times in s of flight, None
        when an estimate never settles within 5 %).
    """
    truth = load_vehicle(spec.vehicle)
    guess = draw_prior(truth, spec.seed)
    flights: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="mavsysid-experiment-") as tmp:
        for kind in spec.kinds:
            model = truth.with_parameters(guess)
            prior = ParameterEstimate(guess, np.diag((PRIOR_SPREAD * np.abs(guess)) ** 2))
            for iteration in range(1, spec.iterations + 1):
                row = _fly(spec, truth, model, prior, kind, iteration, Path(tmp))
                prior = row.pop("_estimate")
                model = truth.with_parameters(prior.value)
                flights.append(row)
    return {"spec": asdict(spec), "key": spec.key(), "truth": truth.theta.tolist(),
            "prior": guess.tolist(), "flights": flights}
