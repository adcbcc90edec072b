"""The model-discrepancy workflow behind ``mavsysid diagnose``.

1. *Where they disagree*: the identified model is replayed along the logged rotor speeds
   (a log faster than `mavsysid.discrepancy.resample.DIAGNOSIS_RATE` averaged down to it)
   and compared with the accelerations of the smoothed pose (`mavsysid.discrepancy.residuals`,
   statistics in `mavsysid.discrepancy.residual_stats`):
   residual per axis, its whiteness (Ljung–Box), the time windows and flight regimes
   (speed, tilt, yaw rate, thrust) where it is large, and the EKF's NIS.
2. *Which effect*: forward selection over the catalogue (`mavsysid.discrepancy.selection`) on the
   first 70 % of the flight.
3. *Add it*: the fitted effects and θ re-fitted with them form the augmented model.
4. *The gap*: residual RMS per axis, Ljung–Box p-values and NIS before and after, on the
   held-out last 30 % of the flight.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from mavsysid.discrepancy.candidates import candidate_library
from mavsysid.discrepancy.filter_nis import nis_pair
from mavsysid.discrepancy.regression import fit_theta
from mavsysid.discrepancy.resample import average_blocks, resample_flight
from mavsysid.discrepancy.residual_stats import (
    AxisStats,
    Where,
    axis_rms,
    ljung_box,
    nis_stats,
    where_large,
)
from mavsysid.discrepancy.residuals import ResidualProblem, SmoothedPose, SmootherSettings
from mavsysid.discrepancy.selection import (
    CandidateScore,
    FittedEffect,
    SelectionSettings,
    Tie,
    forward_select,
)
from mavsysid.estimation import (
    FlightData,
    check_plausible,
    implausibility,
    report_stage,
    vanishing_floor,
    vanishing_parameters,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import InputError

__all__ = [
    "MASS_NOTE",
    "Diagnosis",
    "DiagnosisSettings",
    "Gap",
    "HeldOutGap",
    "check_refits",
    "diagnose_flight",
    "reestimate",
]

#: docs/architecture.md: why a wrong mass cannot be seen from pose and rotor speeds.
MASS_NOTE = ("a wrong mass cannot be detected from pose and rotor speeds: scaling the mass, "
             "c_T, c_M and the inertia by one factor leaves the motion unchanged, so a mass "
             "error is absorbed into θ; weigh the vehicle")


@dataclass(frozen=True)
class DiagnosisSettings:
    """Choices of the diagnosis.

    Attributes
    ----------
    smoother : SmootherSettings
        0.6 s keeps the 0.5 mm / 0.1° noise of the second derivatives near 5 mm/s² and
        0.02 rad/s² while passing the rotors' effect up to ≈ 2 Hz, which is what
        separates a motor lag from a pose delay (they differ in attenuation only).
    selection : SelectionSettings
    holdout : float
        Fraction of the flight (its end) kept out of all fitting.
    candidates : tuple of str or None
        Candidate effect names (the whole catalogue by default).
    window : float
        Length of the time windows of the "where" report, s.
    """

    smoother: SmootherSettings = field(default_factory=SmootherSettings)
    selection: SelectionSettings = field(default_factory=SelectionSettings)
    holdout: float = 0.3
    candidates: tuple[str, ...] | None = None
    window: float = 1.0


@dataclass(frozen=True)
class HeldOutGap:
    """Held-out RMSE of the prior model, the diagnosed θ, and θ with the named effects.

    The ratios pool the axes as `mavsysid.estimation.balance.fit.HoldoutCheck` does: the
    specific force (m/s², three axes) and the angular acceleration (rad/s², three axes),
    each RMSE over the prior model's; below 1 predicts unseen data better than the prior.

    Attributes
    ----------
    prior_rmse, before_rmse, after_rmse : ndarray, shape (6,)
        Per axis, SI.
    rows : int
        Held-out samples compared.
    """

    prior_rmse: np.ndarray
    before_rmse: np.ndarray
    after_rmse: np.ndarray
    rows: int

    @staticmethod
    def _pooled(model: np.ndarray, prior: np.ndarray, axes: slice) -> float:
        m, p = model[axes], prior[axes]
        total = float(np.sum(p**2))
        return float(np.sqrt(np.sum(m**2) / total)) if total > 0 else float("nan")

    def ratios(self, which: str) -> tuple[float, float]:
        """(force, torque) RMSE ratios to the prior model's.

        Parameters
        ----------
        which : {"before", "after"}
            Without or with the named effects.
        """
        model = self.before_rmse if which == "before" else self.after_rmse
        return (self._pooled(model, self.prior_rmse, slice(0, 3)),
                self._pooled(model, self.prior_rmse, slice(3, 6)))

    def as_dict(self) -> dict:
        """JSON-ready: per-axis RMSE lists and the pooled ratios before and after."""
        (fb, tb), (fa, ta) = self.ratios("before"), self.ratios("after")
        return {"rows": self.rows, "prior_rmse": self.prior_rmse.tolist(),
                "before_rmse": self.before_rmse.tolist(),
                "after_rmse": self.after_rmse.tolist(),
                "force_ratio_before": fb, "torque_ratio_before": tb,
                "force_ratio_after": fa, "torque_ratio_after": ta}


@dataclass(frozen=True)
class Gap:
    """The gap between model and measurement before and after the augmentation.

    Attributes
    ----------
    before, after : AxisStats
        On the held-out samples.
    flagged_axes : tuple of int
        Axes on which the named effects act (their fitted contribution at least the size
        of what remains): the headline is computed on these.
    shrink : float
        1 − RMS_after / RMS_before over the flagged axes (each axis in units of its
        remaining noise), or 0 with no effect.
    bic_before, bic_after : float
        Effective BIC of the base and augmented regressions on the training data.
    held_out : HeldOutGap or None
        The held-out RMSE before and after, as ratios to the prior model's.
    """

    before: AxisStats
    after: AxisStats
    flagged_axes: tuple[int, ...]
    shrink: float
    bic_before: float
    bic_after: float
    held_out: HeldOutGap | None = None


@dataclass(frozen=True)
class Diagnosis:
    """The result of `diagnose_flight`.

    Attributes
    ----------
    effects : tuple of FittedEffect
        Named effects, most important first; empty = no significant discrepancy.
    ties : tuple of Tie
    scores : tuple of CandidateScore
    gap : Gap
    where : Where
    theta_identified : ndarray, shape (6,)
        θ the diagnosis started from (the estimate, or the config's).
    theta_before, theta_after : ndarray, shape (6,)
        θ re-fitted on the training data without and with the named effects.
    augmented_effects : tuple of ModelEffect
        The config's known effects plus the named ones: the augmented model.
    t : ndarray, shape (N,)
        Sample times, s.
    residual_before, residual_after : ndarray, shape (N, 6)
        Residuals of the base and augmented models over the whole flight.
    pose : SmoothedPose
    used : ndarray of bool, shape (N,)
        Samples away from the smoother's edges.
    split_time : float
        Start of the held-out part, s.
    notes : tuple of str
    theta_after_sigma : ndarray, shape (6,) or None
        Standard error of ``theta_after`` (None when no effect was named), SI.
    """

    effects: tuple[FittedEffect, ...]
    ties: tuple[Tie, ...]
    scores: tuple[CandidateScore, ...]
    gap: Gap
    where: Where
    theta_identified: np.ndarray
    theta_before: np.ndarray
    theta_after: np.ndarray
    augmented_effects: tuple[ModelEffect, ...]
    t: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray
    pose: SmoothedPose
    used: np.ndarray
    split_time: float
    notes: tuple[str, ...] = field(default_factory=tuple)
    theta_after_sigma: np.ndarray | None = None

    @property
    def significant(self) -> bool:
        """True when at least one effect was named."""
        return bool(self.effects)


def _split(problem: ResidualProblem, used: np.ndarray, settings: DiagnosisSettings
           ) -> tuple[float, np.ndarray, np.ndarray]:
    """Start of the held-out part (s), and the training and held-out sample indices.

    The held-out samples start one smoother window after the split, so that no smoothed
    acceleration mixes the two parts.
    """
    flight = problem.flight
    t = flight.t
    split = float(t[0] + (1.0 - settings.holdout) * flight.duration)
    train = np.flatnonzero(used & (t < split))
    test = np.flatnonzero(used & (t >= split + settings.smoother.window))
    if len(train) < 10 * problem.window_samples or len(test) < 2 * problem.window_samples:
        raise InputError(f"{flight.source}: {flight.duration:.1f} s is too short to diagnose "
                         "(needs ≈ 10 s: training, held-out and smoother edges)")
    return split, train, test


def _shrink(before: AxisStats, after: AxisStats, contribution: np.ndarray, noise: np.ndarray,
            fitted: bool) -> tuple[tuple[int, ...], float]:
    """The axes the named effects act on and the gap's shrink over them (`Gap`).

    Parameters
    ----------
    before, after : AxisStats
        On the held-out samples.
    contribution : ndarray, shape (M, 6)
        Residual before minus after on the training samples: the effects' part.
    noise : ndarray, shape (6,)
        RMS of the augmented model's training residual per axis.
    fitted : bool
        Whether any effect was named (no axes and no shrink otherwise).
    """
    if not fitted:
        return (), 0.0
    size = axis_rms(contribution)
    flagged = tuple(int(a) for a in np.flatnonzero(size >= noise))
    if not flagged:
        flagged = (int(np.argmax(size / noise)),)
    idx = list(flagged)
    b = np.sqrt(np.sum((before.rms[idx] / noise[idx]) ** 2))
    a = np.sqrt(np.sum((after.rms[idx] / noise[idx]) ** 2))
    return flagged, float(1.0 - a / b)


def _start_theta(flight: FlightData, config: VehicleConfig, theta: np.ndarray | None
                 ) -> np.ndarray:
    """θ to diagnose (the config's when None), refused unless finite with c_T, J > 0."""
    theta0 = config.theta.copy() if theta is None else np.asarray(theta, float).reshape(6)
    if not np.all(np.isfinite(theta0)) or theta0[0] <= 0.0 or np.any(theta0[3:] <= 0.0):
        origin = "the estimate's" if theta is not None else f"vehicle {config.name}'s"
        raise InputError(f"{flight.source}: {origin} θ to diagnose must be finite with "
                         f"c_T > 0 and a positive inertia, got {np.array2string(theta0)}")
    return theta0


def _base(problem: ResidualProblem, train: np.ndarray, say: Callable[[str], None]
          ) -> tuple[ResidualProblem, np.ndarray]:
    """The base model and axis weights: θ refitted (all free), or as given (a mask)."""
    rate = f"{len(problem.flight.t)} samples at {1.0 / problem.dt:.4g} Hz"
    if problem.theta_free is None:
        say(f"fitting θ to the flight's accelerations ({rate})")
        return fit_theta(problem, train)
    say(f"residual of the given θ ({rate}, {problem.settings.window * 1e3:.0f} ms smoother)")
    return fit_theta(problem, train, iterations=0)


def diagnose_flight(
    flight: FlightData, config: VehicleConfig, theta: np.ndarray | None = None,
    settings: DiagnosisSettings | None = None, known_effects: Sequence[ModelEffect] = (),
    progress: Callable[[str], None] | None = None, with_nis: bool = True,
    free_theta: np.ndarray | None = None,
) -> Diagnosis:
    """Find, name and fit what the model gets wrong on a flight; show the gap shrink.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
        Mass and geometry (known); its θ is the starting point if ``theta`` is None.
    theta : ndarray, shape (6,), optional
        The identified θ (an ``estimate`` result), SI.
    settings : DiagnosisSettings, optional
    known_effects : sequence of ModelEffect
        Effects already in the model (not candidates).
    progress : callable, optional
        Receives one-line progress messages (default: the estimator's stage listener,
        `mavsysid.estimation.progress.report_stage`).
    with_nis : bool
        Run the parameter EKF for the NIS (needs its compiled kernels).
    free_theta : ndarray of bool, shape (6,), optional
        Given: ``theta`` is an answer (the balance's), not refitted; only these entries
        move with the named effects. None: θ is refitted first, every entry free.

    Returns
    -------
    Diagnosis
    """
    settings = settings or DiagnosisSettings()
    if flight.rotor_count != config.rotor_count:
        raise InputError(f"{flight.source}: {flight.rotor_count} rotor-speed columns, but "
                         f"vehicle {config.name} has {config.rotor_count} rotors")
    if not 0.05 <= settings.holdout <= 0.5:
        raise InputError(f"{flight.source}: held-out fraction {settings.holdout:g}: expected "
                         "0.05 … 0.5")
    theta0 = _start_theta(flight, config, theta)
    known = tuple(known_effects)
    library = tuple(c for c in candidate_library(settings.candidates)
                    if c.name not in {e.name for e in known})
    say = progress or report_stage
    uniform, resampling = average_blocks(*resample_flight(flight))
    problem = ResidualProblem(uniform, config, theta0, settings.smoother, known, resampling,
                              theta_free=None if free_theta is None else
                              np.asarray(free_theta, bool).reshape(6))
    used = problem.keep()
    t = uniform.t
    split, train, test = _split(problem, used, settings)
    base, weights = _base(problem, train, say)
    selection = forward_select(base, library, train, weights, settings.selection, say)
    fitted = tuple(f.effect for f in selection.effects)
    measured, model, pose = base.evaluate()
    r_before = measured - model
    r_after = base.residual(fitted, selection.theta_after)
    nis_before, nis_after, nis_notes = (nis_pair(flight, config, known, fitted, t)
                                        if with_nis else (None, None, []))
    before = AxisStats(axis_rms(r_before[test]), ljung_box(r_before[test], base.block),
                       *nis_stats(nis_before, test))
    after = AxisStats(axis_rms(r_after[test]), ljung_box(r_after[test], base.block),
                      *nis_stats(nis_after, test))
    held_out = HeldOutGap(axis_rms(base.residual((), config.theta)[test]), before.rms,
                          after.rms, len(test))
    noise = axis_rms(r_after[train])
    flagged, shrink = _shrink(before, after, (r_before - r_after)[train], noise, bool(fitted))
    gap = Gap(before, after, flagged, shrink, selection.bic_before, selection.bic_after,
              held_out)
    where = where_large(base, pose, r_before, used, noise, train, settings.window)
    notes = [MASS_NOTE, *([resampling.describe()] if resampling.resampled
                          or resampling.averaged > 1 else []), *nis_notes]
    return Diagnosis(
        effects=selection.effects, ties=selection.ties, scores=selection.scores, gap=gap,
        where=where, theta_identified=theta0, theta_before=selection.theta_before,
        theta_after=selection.theta_after, augmented_effects=(*known, *fitted), t=t,
        residual_before=r_before, residual_after=r_after, pose=pose, used=used,
        split_time=split, notes=tuple(notes), theta_after_sigma=selection.theta_after_sigma,
    )


def check_refits(source: str, diagnosis: Diagnosis, config: VehicleConfig) -> tuple[str, ...]:
    """Refuse (`JobFailedError`, one line) an answer that is physically impossible.

    The answer is θ refitted with the named effects, judged under all of the model's
    effects: an entry the named effects take over (c_D when ``rotor_drag_linear`` carries
    the rotor drag) may then be ≈ 0, within its σ (`mavsysid.estimation.checks`).
    θ refitted *without* them is what the mismatch does to the paper's model: with effects
    named, an impossible one is a note (the named effects explain it), not a refusal;
    with none named it is the answer itself.

    Parameters
    ----------
    source : str
        The log, named first in a refusal.
    diagnosis : Diagnosis
    config : VehicleConfig
        The vehicle: its θ is the prior, its top rotor speed bounds a vanishing c_D.

    Returns
    -------
    tuple of str
        Notes for the diagnosis (θ refitted without the named effects impossible).
    """
    prior, n_max = config.theta, config.limits.rotor_speed_max
    after = diagnosis.augmented_effects
    check_plausible(source, diagnosis.theta_after, diagnosis.theta_after_sigma, prior,
                    what="θ refitted with the named effects" if diagnosis.effects
                    else "θ refitted without effects",
                    may_vanish=vanishing_parameters(e.name for e in after),
                    floor=vanishing_floor(after, float(diagnosis.theta_after[0]), n_max))
    if not diagnosis.effects:
        return ()
    known = after[:len(after) - len(diagnosis.effects)]
    reason = implausibility(diagnosis.theta_before, None, prior,
                            may_vanish=vanishing_parameters(e.name for e in known),
                            floor=vanishing_floor(known, float(diagnosis.theta_before[0]),
                                                  n_max))
    if reason is None:
        return ()
    return (f"θ refitted without the named effects is not physically possible ({reason}): "
            "the mismatch they explain",)


def reestimate(flight: FlightData, config: VehicleConfig, effects: Sequence[ModelEffect],
               refine: bool = False) -> Any:
    """Step 3 with the estimator: θ and ``effects``' parameters estimated jointly.

    Runs `mavsysid.estimation.estimate_with_effects` (the EKF, and the batch refinement if
    ``refine``) with ``effects`` as the model's complete list (a diagnosis'
    ``augmented_effects``, or only the known ones for the comparison); their values
    are the start of the fit.

    Returns
    -------
    EstimationResult
        (`mavsysid.estimation.results`; imported lazily, as the estimator loads compiled kernels.)
    """
    from mavsysid.estimation import (
        EstimatorSettings,
        estimate_with_effects,
    )

    return estimate_with_effects(flight, config, tuple(effects),
                                 EstimatorSettings(refine=refine), fit_effects=True)
