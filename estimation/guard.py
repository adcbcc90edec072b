"""The estimator's guard: a diverging filter, and a θ the force balance contradicts.

Divergence. A consistent filter's normalised innovation squared (NIS) averages the
measurement dimension m = 6; its mean over a window of w samples lies below the
χ²(m w)/w 99.9 % bound. A model that cannot follow the log (θ far off, c_T 70× too
small) makes the innovations grow by orders of magnitude. Model mismatch on good flights
(wind, motor lag, a smoothed on-board pose) raises the NIS several-fold too, so the
bound is widened by `NIS_FACTOR`: the filter counts as diverged when the median of its
windowed mean NIS over the flight's second half exceeds `NIS_FACTOR` × the bound, or when
its θ is physically impossible or `PRIOR_FACTOR_MAX` off the prior
(`mavsysid.estimation.plausibility`). A diverged filter restarts from the equation-error
θ with its measurement σ scaled by √(NIS level / m) (at least 1): the innovations
measure the pose noise the filter met, which a smoothed on-board pose hides from the
log's white residual (`mavsysid.estimation.pose_noise`).

Contradiction. The final θ and the equation-error θ (`mavsysid.estimation.equation_error_fit`)
are two estimates from one log, both consistent when the model fits it. They disagree
when they differ by more than `AGREEMENT_SIGMAS` × √(σ² + σ_EE²) *and* by more than the
relative tolerance `AGREEMENT_TOLERANCE` (5 %, c_D 15 %: the accuracy asked of the
estimator, below which model mismatch biases both fits by different amounts without
either being wrong). A disagreement is what a model mismatch looks like (a motor lag, a
body drag, a drag law linear in rotor speed): the estimator has widened that parameter's
σ to hold it (`mavsysid.estimation.robust_covariance.disagreement_widening`) and says
so, and `mavsysid diagnose` takes it from there. Only a disagreement as large as
`UNDETERMINED_RELATIVE` of the value (σ widened to half the value: the log determines
nothing about the parameter) is refused.
"""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.plausibility import implausibility
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS
from mavsysid.vehicle.linearization import MEAS_DIM
from scipy.stats import chi2

from mavsysid.errors import JobFailedError

__all__ = ["AGREEMENT_SIGMAS", "AGREEMENT_TOLERANCE", "CORRELATED_RHO", "DIVERGED_NIS",
           "NIS_FACTOR", "NIS_WINDOW", "UNDETERMINED_RELATIVE", "check_agreement",
           "correlated_noise_sigma", "disagreements", "divergence", "nis_level"]

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
AGREEMENT_TOLERANCE = np.array([0.05, 0.15, 0.05, 0.05, 0.05, 0.05])

#: A disagreement of this fraction of the value leaves the parameter undetermined (the
#: σ that holds it is half the value: `mavsysid.estimation.plausibility`'s "the log does
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
        The filter's final θ.
    prior : ParameterEstimate
        The prior (the vehicle file's θ and σ).
    may_vanish : ndarray of bool, shape (6,), optional
        θ entries the model lets be ≈ 0 (`mavsysid.estimation.plausibility.vanishing_parameters`).
    floor : ndarray, shape (6,), optional
        Their least possible values (`mavsysid.estimation.plausibility.vanishing_floor`).
    """
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
    """Which parameters the two estimates disagree on (the rule above), bool (6,).

    Parameters
    ----------
    final, ee : ParameterEstimate
        The estimator's θ (σ before any widening) and the equation-error θ, SI.
    """
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
    delta = final.value - ee.value
    spread = np.sqrt(final.sigma**2 + ee.sigma**2)
    bad = disagreements(final, ee) & (np.abs(delta) >= UNDETERMINED_RELATIVE
                                      * np.abs(final.value))
    for i in np.flatnonzero(bad):
        name, unit = PARAMETER_NAMES[i], PARAMETER_UNITS[PARAMETER_NAMES[i]]
        raise JobFailedError(
            f"{source}: the estimate {name} = {final.value[i]:.4g} ± {final.sigma[i]:.2g} "
            f"{unit} contradicts the log's force and torque balance ({name} = "
            f"{ee.value[i]:.4g} ± {ee.sigma[i]:.2g} {unit}, {abs(delta[i]) / spread[i]:.1f} σ "
            "apart), so far that the log does not determine it; the model does not fit this "
            "log as the filter assumed (mavsysid diagnose names what it misses)")
