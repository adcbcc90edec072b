"""The filter's guard: a diverging filter restarted or refused, and a θ the balance contradicts.

**Divergence** (`divergence`). A consistent filter's normalised innovation squared (NIS)
averages the measurement dimension m = 6; its mean over a window of w samples lies below
the χ²(m w)/w 99.9 % bound. A model that cannot follow the log (θ far off, c_T 70× too
small) makes the innovations grow by orders of magnitude; model mismatch on good flights
(wind, motor lag, a smoothed on-board pose) raises the NIS several-fold too, so the bound
is widened by `NIS_FACTOR`. The filter counts as diverged when the median of its windowed
mean NIS over the flight's second half exceeds that, when its θ is physically impossible
or far off the prior (`mavsysid.estimation.checks`), or when its state overflowed.

**Restart** (`guarded_filter`). A diverged filter restarts from the equation-error θ (the
force and torque balance's, with the prior) with its measurement σ scaled by
√(NIS level / m): the innovations measure the pose noise the filter met, which a smoothed
on-board pose hides from the log's white residual. A pose whose noise drifts makes the
innovations correlated; `decorrelated_attempt` raises σ to the white σ of equal
information (`correlated_noise_sigma`). After `MAX_RESTARTS` the estimate is refused
(`JobFailedError`, one line); the batch refinement never starts from a diverged filter.

**The pose's noise** (`measured_pose_noise`, `pose_sigma`). Each coordinate is fitted by
a local cubic over `NOISE_WINDOW` samples; the residual of a local polynomial fit is the
white part of the noise times √(1 − c₀) (c₀ the fit's centre weight), and its robust scale
(1.4826 × MAD) ignores the odd outlier and manoeuvre. Attitude: a small rotation δ moves q
by |δ|/2, so the per-axis angle σ is 2 √(Σ σ_c² / 3). An on-board estimator's pose is
smoothed: its white residual collapses although its error does not, so `pose_sigma` takes
the measured σ only when it clearly exceeds the σ assumed for the pose's source
(`NOISE_TOLERANCE`).

**Contradiction** (`check_agreement`). The final θ and the equation-error θ are two
estimates from one log, both consistent when the model fits it. They disagree when they
differ by more than `AGREEMENT_SIGMAS` × √(σ² + σ_EE²) *and* by more than the relative
tolerance `AGREEMENT_TOLERANCE` (5 %, c_D 15 %). A disagreement is what a model mismatch
looks like: the estimator widens that parameter's σ to hold it
(`mavsysid.estimation.robust.disagreement_widening`) and says so, and ``mavsysid
diagnose`` takes it from there. Only a disagreement as large as `UNDETERMINED_RELATIVE` of
the value is refused. Nuisance quantities beyond θ are not judged here.
"""

from __future__ import annotations

import math

import numpy as np
from mavsysid.estimation.checks import implausibility, vanishing_floor, vanishing_parameters
from mavsysid.estimation.filter.ekf import FilterOverflow, FilterRun
from mavsysid.estimation.filter.likelihood import ModelTerms, reference_terms
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.estimation.signals import savgol_kernel
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, VehicleConfig
from mavsysid.vehicle.linearization import MEAS_DIM, initial_state_sigma
from mavsysid.vehicle.model_effects import ModelEffect
from mavsysid.vehicle.parameters import PAPER_THETA
from mavsysid.vehicle.rotation import continuous_sign
from scipy.ndimage import convolve1d
from scipy.stats import chi2

from mavsysid.errors import JobFailedError

__all__ = ["AGREEMENT_SIGMAS", "AGREEMENT_TOLERANCE", "CORRELATED_RHO", "DECORRELATION_PASSES",
           "DIVERGED_NIS", "MAX_RESTARTS", "NIS_FACTOR", "NIS_WINDOW", "NOISE_TOLERANCE",
           "NOISE_WINDOW", "OVERFLOW_SHARE", "UNDETERMINED_RELATIVE", "check_agreement",
           "correlated_noise_sigma", "decorrelated_attempt", "disagreements", "divergence",
           "failure_phrase", "filter_attempt", "guarded_filter", "measured_pose_noise",
           "nis_level", "pose_sigma"]


#: Window of the NIS mean, s.
NIS_WINDOW = 1.0

#: Windowed mean NIS beyond this multiple of its 99.9 % χ² bound is a diverged filter.
NIS_FACTOR = 20.0

#: Lag-one autocorrelation of the innovations above which the pose noise counts as
#: correlated (a consistent filter's innovations are white, ρ ≈ 0; a few samples'
#: smoothing gives ≈ 0.8), and the largest one believed.
CORRELATED_RHO = 0.9
_RHO_MAX = 0.999

#: How `divergence` starts the phrase of a run whose innovations grew beyond the bound.
DIVERGED_NIS = "mean normalised innovation squared"

#: Agreement rule of the cross-check: sigmas and relative tolerance per parameter.
AGREEMENT_SIGMAS = 3.0
AGREEMENT_TOLERANCE = np.array([q.tolerance for q in PAPER_THETA])

#: A disagreement of this fraction of the value leaves the parameter undetermined (the
#: σ that holds it is half the value: `mavsysid.estimation.checks`'s "the log does
#: not determine it"), and the estimate is refused.
UNDETERMINED_RELATIVE = 0.5


def nis_level(t: np.ndarray, nis: np.ndarray) -> tuple[float, float]:
    """Median windowed mean NIS over the flight's second half, and its 99.9 % χ² bound.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s.
    nis : ndarray, shape (N,)
        The filter's NIS per sample (the first is not an innovation).

    Returns
    -------
    level, bound : float
        NaN level when the half is shorter than one window; inf when not finite.
    """
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = max(1, round(NIS_WINDOW / dt))
    bound = float(chi2.ppf(0.999, MEAS_DIM * w)) / w
    x = np.asarray(nis, float)[1:]
    half = x[x.size // 2:]
    if not np.all(np.isfinite(half)):
        return float("inf"), bound
    if half.size < w:
        return float("nan"), bound
    return float(np.median(np.convolve(half, np.ones(w) / w, mode="valid"))), bound


def correlated_noise_sigma(innovation: np.ndarray) -> tuple[float, float]:
    """Position and attitude σ of a pose whose noise is correlated in time; NaN: white.

    An on-board estimator's pose error drifts over a fraction of a second, yet the filter
    weighs every 500 Hz sample as independent: it becomes overconfident long before θ is
    determined, fits inertia to the drift and can lock there (or overflow). For AR(1)
    noise of σ s and lag-one correlation ρ a mean over N samples has the variance of N
    (1 − ρ) / (1 + ρ) independent ones, so the white σ that carries the same information
    is s √((1 + ρ) / (1 − ρ)). s is the RMS of the innovations over the three position
    (attitude) channels, ρ the median of their lag-one autocorrelations (at most
    `_RHO_MAX`). Both are NaN (no change) unless one group's ρ exceeds `CORRELATED_RHO`:
    noise smoothed over a few samples (ρ ≈ 0.8) is left to the white σ.

    Parameters
    ----------
    innovation : ndarray, shape (N, 6)
        The filter's innovations [δp (m), δφ (rad)]; the first row is not one.

    Returns
    -------
    tuple of 2 float
        σ of position (m) and attitude (rad), or NaN.
    """
    y = np.asarray(innovation, float)[1:]
    y = y[np.all(np.isfinite(y), axis=1)]
    if y.shape[0] < 3:
        return float("nan"), float("nan")
    y = y - y.mean(axis=0)
    power = np.sum(y * y, axis=0)
    rho = np.sum(y[1:] * y[:-1], axis=0) / np.where(power > 0.0, power, 1.0)
    groups = (slice(0, 3), slice(3, 6))
    r = np.clip([np.median(rho[g]) for g in groups], 0.0, _RHO_MAX)
    if not np.max(r) > CORRELATED_RHO:
        return float("nan"), float("nan")
    rms = [float(np.sqrt(np.mean(power[g]) / y.shape[0])) for g in groups]
    out = [s * float(np.sqrt((1.0 + c) / (1.0 - c))) for s, c in zip(rms, r, strict=True)]
    return out[0], out[1]


def divergence(t: np.ndarray, nis: np.ndarray, theta: ParameterEstimate,
               prior: ParameterEstimate, may_vanish: np.ndarray | None = None,
               floor: np.ndarray | None = None) -> str | None:
    """Why a filter run counts as diverged, as one phrase; None when it did not.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s.
    nis : ndarray, shape (N,)
        The filter's NIS per sample.
    theta : ParameterEstimate
        The filter's final estimate (its θ is judged; nuisance quantities are not).
    prior : ParameterEstimate
        The prior (the vehicle file's θ and σ).
    may_vanish : ndarray of bool, shape (6,), optional
        θ entries the model lets be ≈ 0 (`mavsysid.estimation.checks.vanishing_parameters`).
    floor : ndarray, shape (6,), optional
        Their least possible values (`mavsysid.estimation.checks.vanishing_floor`).
    """
    theta, prior = theta.theta, prior.theta
    reason = implausibility(theta.value, theta.sigma, prior.value, prior.sigma, may_vanish,
                            floor)
    if reason is not None:
        return reason
    level, bound = nis_level(t, nis)
    if level > NIS_FACTOR * bound:
        return (f"{DIVERGED_NIS} {level:.3g} over {NIS_WINDOW:g} s "
                f"windows, {level / bound:.3g}× its χ² bound {bound:.3g}")
    return None


def disagreements(final: ParameterEstimate, ee: ParameterEstimate) -> np.ndarray:
    """Which entries of θ the two estimates disagree on (the rule above), bool (6,).

    Parameters
    ----------
    final, ee : ParameterEstimate
        The estimator's θ (σ before any widening) and the equation-error θ, SI (nuisance
        quantities beyond θ are not compared).
    """
    final, ee = final.theta, ee.theta
    delta = np.abs(final.value - ee.value)
    spread = np.sqrt(final.sigma**2 + ee.sigma**2)
    return (delta > AGREEMENT_SIGMAS * spread) & (delta > AGREEMENT_TOLERANCE * np.abs(ee.value))


def check_agreement(source: str, final: ParameterEstimate, ee: ParameterEstimate) -> None:
    """Refuse (`JobFailedError`, one line) a final θ the equation-error fit leaves undetermined.

    A parameter on which the two disagree (`disagreements`) by at least
    `UNDETERMINED_RELATIVE` of the final value is refused; a smaller disagreement is a
    model mismatch the estimator reports with a widened σ.

    Parameters
    ----------
    source : str
        The log, named first.
    final, ee : ParameterEstimate
        The estimator's θ (σ before any widening) and the equation-error θ, SI.
    """
    bad = disagreements(final, ee)
    final, ee = final.theta, ee.theta
    delta = final.value - ee.value
    spread = np.sqrt(final.sigma**2 + ee.sigma**2)
    bad &= (np.abs(delta) >= UNDETERMINED_RELATIVE
                                      * np.abs(final.value))
    for i in np.flatnonzero(bad):
        name, unit = PARAMETER_NAMES[i], PARAMETER_UNITS[PARAMETER_NAMES[i]]
        raise JobFailedError(
            f"{source}: the estimate {name} = {final.value[i]:.4g} ± {final.sigma[i]:.2g} "
            f"{unit} contradicts the log's force and torque balance ({name} = "
            f"{ee.value[i]:.4g} ± {ee.sigma[i]:.2g} {unit}, {abs(delta[i]) / spread[i]:.1f} σ "
            "apart), so far that the log does not determine it; the model does not fit this "
            "log as the filter assumed (mavsysid diagnose names what it misses)")


#: Filter passes that may raise the measurement σ for correlated pose noise.
DECORRELATION_PASSES = 3

#: Share of an overflowed run's innovations (the first ones) that measure the pose noise.
OVERFLOW_SHARE = 0.75

#: Restarts of a diverged filter from the equation-error θ before the estimate is refused.
MAX_RESTARTS = 2


def failure_phrase(reason: str | None) -> str:
    """What a failed run did: diverged (innovations, overflow) or ended at an impossible θ.

    Parameters
    ----------
    reason : str or None
        `mavsysid.estimation.filter.guard.divergence`'s phrase, or "the state overflowed".
    """
    if reason is None or reason.startswith((DIVERGED_NIS, "the state overflowed")):
        return f"diverged ({reason})"
    return f"ended at a θ that is not physical ({reason})"


def filter_attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
) -> tuple[ModelTerms | None, FilterRun | None, str | None]:
    """One filter run: terms, run and why it diverged (None: it did not).

    An entry of θ that ``effects`` let vanish (c_D with ``rotor_drag_linear``) may be ≈ 0,
    or as low as physics allows beside them (`mavsysid.estimation.checks`).
    """
    terms, run, reason, _ = _attempt(flight, effects, config, start, prior, sigma)
    return terms, run, reason


def _attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
) -> tuple[ModelTerms | None, FilterRun | None, str | None, np.ndarray]:
    """`filter_attempt` and the run's innovations (N, 6); of an overflowed run, those
    of its first `OVERFLOW_SHARE` of samples (its last ones are the blow-up)."""
    state_sigma = initial_state_sigma(sigma[0], sigma[1], float(flight.t[1] - flight.t[0]))
    try:
        terms, run = reference_terms(flight, effects, config, start, sigma, state_sigma)
    except FilterOverflow as error:
        innovation = error.innovation[:int(OVERFLOW_SHARE * error.innovation.shape[0])]
        return None, None, "the state overflowed", innovation
    except JobFailedError:
        return None, None, "the state overflowed", np.empty((0, MEAS_DIM))
    may_vanish = vanishing_parameters(e.name for e in effects)
    floor = vanishing_floor(effects, float(run.estimate.value[0]),
                            config.limits.rotor_speed_max)
    return terms, run, divergence(run.history.t, run.history.nis, run.estimate, prior,
                                  may_vanish, floor), run.history.innovation


def decorrelated_attempt(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    start: ParameterEstimate, prior: ParameterEstimate, sigma: tuple[float, float],
    notes: list[str],
) -> tuple[ModelTerms | None, FilterRun | None, str | None, tuple[float, float]]:
    """`filter_attempt`, rerun with σ widened while its innovations are correlated.

    A pose whose noise drifts (an on-board estimator's) makes the innovations correlated;
    the filter at white-noise σ is overconfident and fits θ to the drift. Each pass
    raises σ to `mavsysid.estimation.filter.guard.correlated_noise_sigma` of the last run's
    innovations (an overflowed run's too) when that is clearly larger (a filter at too
    small a σ follows the drift and sees only part of it, hence up to
    `DECORRELATION_PASSES` passes). Returns also the σ of the returned run.
    """
    terms, run, reason, innovation = _attempt(flight, effects, config, start, prior, sigma)
    for _ in range(DECORRELATION_PASSES):
        target = correlated_noise_sigma(innovation)
        wider = tuple(t if t > NOISE_TOLERANCE * s else s
                      for t, s in zip(target, sigma, strict=True))
        if wider == sigma:
            break
        sigma = wider  # type: ignore[assignment]
        notes.append(f"the filter's innovations are correlated in time (pose noise that "
                     f"drifts): measurement σ raised to {1000 * sigma[0]:.2g} mm, "
                     f"{math.degrees(sigma[1]):.2g}°, the white σ of equal information")
        terms, run, reason, innovation = _attempt(flight, effects, config, start, prior,
                                                  sigma)
    return terms, run, reason, sigma


def guarded_filter(
    flight: FlightData, effects: tuple[ModelEffect, ...], config: VehicleConfig,
    priors: tuple[ParameterEstimate, ParameterEstimate], sigma: tuple[float, float],
    state_sigma: tuple[float, float, float, float], ee: ParameterEstimate | None,
    notes: list[str], restart: bool = True,
) -> tuple[ModelTerms, FilterRun, ParameterEstimate, tuple[float, float]]:
    """Step 1 with the divergence guard (`mavsysid.estimation.filter.guard`).

    Filter from ``start``; if it diverged, restart from the equation-error θ with the
    prior's covariance and the measurement σ widened to the innovations' level (at most
    `MAX_RESTARTS` times, while a restart has something new to try); refuse if it still
    diverges, unless widening σ for correlated pose noise (`decorrelated_attempt`, from
    the equation-error θ) ends the divergence. ``priors`` is (the prior, the filter's
    start). Returns the terms, the run, and the start and measurement σ the run used.
    ``restart`` False refuses at the first failure (another estimate answers instead).
    """
    prior, start = priors
    if ee is None:
        terms, run = reference_terms(flight, effects, config, start, sigma, state_sigma)
        return terms, run, start, sigma
    terms, run, reason = filter_attempt(flight, effects, config, start, prior, sigma)
    if reason is not None and not restart:
        raise JobFailedError(f"{flight.source}: the parameter filter {failure_phrase(reason)}")
    from_ee = ParameterEstimate(ee.value, prior.covariance, prior.names)
    for _ in range(MAX_RESTARTS):
        if reason is None:
            break
        level = nis_level(run.history.t, run.history.nis)[0] if run is not None else np.nan
        widen = float(np.sqrt(level / MEAS_DIM)) if np.isfinite(level) else 1.0
        widen = max(widen, 1.0)
        if start is from_ee and widen == 1.0:
            break  # the same run again would diverge again
        start, sigma = from_ee, (sigma[0] * widen, sigma[1] * widen)
        notes.append(f"the filter {failure_phrase(reason)}; restarted from the equation-error θ "
                     f"with the measurement σ × {widen:.3g} (the innovations' level): "
                     f"{1000 * sigma[0]:.2g} mm, {math.degrees(sigma[1]):.2g}°")
        terms, run, reason = filter_attempt(flight, effects, config, start, prior, sigma)
    if reason is not None:  # last resort: pose noise that drifts (an on-board estimator's)
        start = from_ee
        terms, run, reason, sigma = decorrelated_attempt(flight, effects, config, start,
                                                         prior, sigma, notes)
    if reason is not None or terms is None or run is None:
        raise JobFailedError(" ".join(
            f"{flight.source}: the parameter filter {failure_phrase(reason)}, also when restarted "
            "from the equation-error θ; the model cannot follow this log".split()))
    return terms, run, start, sigma


#: Samples of the local cubic fit (odd).
NOISE_WINDOW = 9


#: The measured σ replaces the assumed one when larger by more than this factor.
NOISE_TOLERANCE = 1.5


_MAD_TO_SIGMA = 1.4826


def _white_sigma(x: np.ndarray) -> np.ndarray:
    """Robust σ of the white part of each column of x (N, k)."""
    c = savgol_kernel(NOISE_WINDOW, 3, 0, 1.0)
    e = (x - convolve1d(x, c, axis=0, mode="nearest"))[NOISE_WINDOW:-NOISE_WINDOW]
    mad = np.median(np.abs(e - np.median(e, axis=0)), axis=0)
    return _MAD_TO_SIGMA * mad / np.sqrt(1.0 - c[NOISE_WINDOW // 2])


def measured_pose_noise(flight: FlightData) -> tuple[float, float]:
    """White-noise σ of position (m) and attitude (rad, per axis) in the longest segment."""
    if len(flight.segment_starts) > 1:
        flight = flight.segment(flight.longest_segment())
    if len(flight) < 3 * NOISE_WINDOW:
        return 0.0, 0.0
    q = continuous_sign(flight.quaternion)
    position = float(np.median(_white_sigma(np.asarray(flight.position, float))))
    attitude = float(2.0 * np.sqrt(np.sum(_white_sigma(q) ** 2) / 3.0))
    return position, attitude


def pose_sigma(flight: FlightData, assumed: tuple[float, float]
               ) -> tuple[tuple[float, float], str | None]:
    """Measurement σ (m, rad) for the filter, and a note when the log changed it.

    Parameters
    ----------
    flight : FlightData
    assumed : tuple of 2 float
        σ assumed for the pose source (m, rad): the floor.
    """
    measured = measured_pose_noise(flight)
    used = tuple(m if m > NOISE_TOLERANCE * a else a
                 for m, a in zip(measured, assumed, strict=True))
    if used == tuple(assumed):
        return tuple(assumed), None  # type: ignore[return-value]
    return used, (  # type: ignore[return-value]
        f"measurement σ measured from the pose (local-cubic residual, robust): "
        f"{1000 * measured[0]:.2g} mm, {np.degrees(measured[1]):.2g}°; used "
        f"{1000 * used[0]:.2g} mm, {np.degrees(used[1]):.2g}° (floor: the assumed "
        f"{1000 * assumed[0]:.2g} mm, {np.degrees(assumed[1]):.2g}°)")
