"""Fitting model effects' parameters jointly with θ: maximum likelihood through the EKF.

Given effects with starting values (a vehicle config's ``[effects.NAME]`` tables, or the
candidates of the discrepancy workflow), their parameters ψ are estimated from the same
flight as θ. The filter's innovation log-likelihood

    ℓ(ψ, s) = Σ_k log N(y_k; 0, S_k)        (s: the process-noise scale of `noise_fit`)

is the marginal likelihood of the poses given ψ and s, with θ and the states integrated
out by the filter under θ's prior. Its maximum over (ψ, s) is the joint ML estimate, and
θ̂(ψ̂) is then θ's estimate under the fitted effects. σ(ψ) comes from the observed
information: the inverse of −∂²ℓ/∂ψ² at the optimum (central differences at a step of
about one σ, so it is the curvature of the likelihood over the confidence interval);
the 95 % interval is ψ̂ ± 1.96 σ. Parameters that have a sign by their meaning (a time
constant, a drag coefficient: the config schema's table) are kept in their range; an
estimate at the bound gets its σ from the curvature just inside it.

Why through the likelihood rather than an augmented filter state: the effects act
through channels that are not smooth functions inside the filter — a pose delay re-times
the measurements, a motor lag filters the whole rotor-speed log — and their physics is
defined once, in numpy, for truth and model (`mavsysid.vehicle.model_effects`). The likelihood
needs only to *evaluate* an effect at given values, so every catalogue effect (and any
added later) is fitted the same way, and the filter kernel stays the paper's.

The optimiser is a damped Newton method in scaled units (ψ / the size of the effect's
starting values, `fit_scales`; log10 s) with a finite-difference Hessian. The ψ–s cross
terms are taken as zero: in a Gaussian likelihood, parameters of the mean and of the
covariance are (asymptotically) orthogonal, and this halves the evaluations. s starts at
the config's densities (1).

Cost: one filter pass per evaluation (≈ 0.1 s for 30 s at 100 Hz); a Newton iteration
takes 2(P + 1) + 2P(P − 1) passes for P effect parameters, 2–4 iterations usually. Wrench
effects are evaluated on a previous pass (`mavsysid.estimation.effect_channels`), so their fit
repeats with the reference moved to the optimum until θ settles (usually once more).

The uncertainty of ψ is carried into θ's: with J = dθ̂/dψ (from the same finite
differences), Σ_θ ← Σ_θ|ψ + J Σ_ψ Jᵀ (`EffectFit.theta_covariance_increment`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from mavsysid.estimation.effect_channels import ModelTerms, WrenchReference, has_wrench, model_terms
from mavsysid.estimation.ekf import FilterRun, ParameterEKF
from mavsysid.estimation.flight_data import FlightData
from mavsysid.estimation.noise_fit import NOISE_SCALE_BOUNDS, scaled_noise
from mavsysid.estimation.results import FittedEffect, ParameterEstimate
from mavsysid.vehicle.config import VehicleConfig

# The schema's table of parameters that have a sign (tau ≥ 0 …): fitted values must load
# back from the config they are written to. One table, so it is borrowed, not copied.
from mavsysid.vehicle.config_schema import EFFECT_PARAMETER_SIGNS
from mavsysid.vehicle.model_effects import ModelEffect

__all__ = ["EffectFit", "EffectFitSettings", "fit_effects", "fit_scales", "reference_terms"]

_StateSigma = tuple[float, float, float, float]


@dataclass(frozen=True)
class EffectFitSettings:
    """Choices of the effect fit.

    Attributes
    ----------
    max_iterations : int
        Newton iterations per reference pass.
    reference_passes : int
        Most passes with the wrench reference moved to the optimum (wrench effects only).
    theta_tolerance : float
        Relative change of the reference θ below which the passes stop.
    max_step : float
        Largest Newton step per parameter, in units of its ``scale``.
    """

    max_iterations: int = 8
    reference_passes: int = 3
    theta_tolerance: float = 2e-3
    max_step: float = 3.0


@dataclass(frozen=True)
class EffectFit:
    """Fitted effects, the noise level, and the filter at the optimum.

    Attributes
    ----------
    effects : tuple of FittedEffect
        Each effect with its fitted values and σ.
    covariance : ndarray, shape (P, P)
        Covariance of all P fitted parameters, stacked in effect order, SI.
    theta_sensitivity : ndarray, shape (6, P)
        dθ̂/dψ of the filter's final θ, SI.
    noise_scale : float
        Fitted process-noise scale (as `mavsysid.estimation.noise_fit`).
    noise_at_bound : bool
        The noise scale sits at the edge of its range (held there).
    config : VehicleConfig
        The config with the fitted noise densities.
    terms : ModelTerms
        The flight in the model's terms at the fitted effects.
    run : FilterRun
        The filter at the optimum.
    evaluations : int
        Filter passes of the Newton search.
    """

    effects: tuple[FittedEffect, ...]
    covariance: np.ndarray
    theta_sensitivity: np.ndarray
    noise_scale: float
    noise_at_bound: bool
    config: VehicleConfig
    terms: ModelTerms
    run: FilterRun
    evaluations: int

    def theta_covariance_increment(self) -> np.ndarray:
        """J Σ_ψ Jᵀ, the part of θ's covariance due to the effects' uncertainty, (6, 6)."""
        J = self.theta_sensitivity
        return J @ self.covariance @ J.T


def _lower_bounds(effect: ModelEffect) -> np.ndarray:
    """Least value of each parameter, SI: the config schema's signs (−inf: any sign)."""
    signs = [EFFECT_PARAMETER_SIGNS.get((effect.name, p.name)) for p in effect.parameters]
    return np.array([-np.inf if s is None else 0.0 if s == "nonnegative" else 1e-6 * p.scale
                     for s, p in zip(signs, effect.parameters, strict=True)])


def fit_scales(effect: ModelEffect) -> np.ndarray:
    """The unit each parameter is fitted in (SI, shape (P,)): the size of its effect's start.

    The search steps by a tenth of a unit at first, at most `EffectFitSettings.max_step`
    units per iteration. The catalogue's scales are those of a 1–2 kg vehicle; a
    Crazyflie's linear rotor drag is 100× smaller, and a first step of the catalogue's
    size makes its drag ten times the truth and the filter overflow. The largest starting
    value of the effect's parameters (they share a unit: offsets, wind, drag terms) is the
    vehicle's own size; a start at zero, or below 10⁻³ of the catalogue scale, keeps the
    catalogue's.

    Parameters
    ----------
    effect : ModelEffect
        The effect, its values the start of the fit (SI).
    """
    catalogue = effect.parameter_scales()
    size = float(np.max(np.abs(effect.values))) if effect.values.size else 0.0
    return np.where(size > 1e-3 * catalogue, size, catalogue)


def _filter(config: VehicleConfig, prior: ParameterEstimate, sigma: tuple[float, float],
            state_sigma: _StateSigma, terms: ModelTerms) -> FilterRun:
    return ParameterEKF(config, prior, sigma).run(terms.flight, state_sigma, terms.wrench)


def _settled(old: np.ndarray, new: np.ndarray, tolerance: float) -> bool:
    return bool(np.max(np.abs(new - old) / np.maximum(np.abs(old), 1e-300)) < tolerance)


def reference_terms(
    flight: FlightData, effects: Sequence[ModelEffect], config: VehicleConfig,
    prior: ParameterEstimate, sigma: tuple[float, float], state_sigma: _StateSigma,
    settings: EffectFitSettings | None = None,
) -> tuple[ModelTerms, FilterRun]:
    """The model terms of effects with *known* values, and the filter run on them.

    Without wrench effects this is one pass; with them, passes repeat with the wrench
    evaluated on the previous pass until θ settles (`EffectFitSettings.theta_tolerance`).
    ``config`` sets the noise of these passes.
    """
    settings = settings or EffectFitSettings()
    terms = model_terms(flight, effects, config)
    run = _filter(config, prior, sigma, state_sigma, terms)
    if not has_wrench(effects):
        return terms, run
    for _ in range(settings.reference_passes):
        reference = WrenchReference(run.states, run.estimate.value)
        terms = model_terms(flight, effects, config, reference)
        theta = run.estimate.value
        run = _filter(config, prior, sigma, state_sigma, terms)
        if _settled(theta, run.estimate.value, settings.theta_tolerance):
            break
    return terms, run


@dataclass
class _Objective:
    """ℓ(u, v) in scaled units (u = ψ / scale, v = log10 s), cached per point."""

    evaluate: Callable[[np.ndarray, float], tuple[float, np.ndarray]]
    cache: dict = field(default_factory=dict)

    def __call__(self, u: np.ndarray, v: float) -> tuple[float, np.ndarray]:
        key = (*np.round(u, 12), round(v, 12))
        if key not in self.cache:
            self.cache[key] = self.evaluate(u, v)
        return self.cache[key]


@dataclass
class _Derivatives:
    ll: float
    g: np.ndarray         # ∂ℓ/∂u (P,)
    H: np.ndarray         # ∂²ℓ/∂u² (P, P)
    gv: float             # ∂ℓ/∂v
    hv: float             # ∂²ℓ/∂v²
    dtheta: np.ndarray    # ∂θ̂/∂u (6, P)


def _derivatives(f: _Objective, u: np.ndarray, v: float, h: np.ndarray, h_v: float,
                 fit_noise: bool, lower: np.ndarray) -> _Derivatives:
    """Central differences of ℓ: gradient, Hessian over u (with cross terms), v block.

    A parameter within h of its lower bound is differenced about bound + h instead: the
    stencil must not leave the range where the effect is defined.
    """
    P = u.size
    u = np.maximum(u, lower + h)
    ll0, _ = f(u, v)
    g, H, dtheta = np.zeros(P), np.zeros((P, P)), np.zeros((6, P))
    E = np.eye(P) * h
    for i in range(P):
        lp, tp = f(u + E[i], v)
        lm, tm = f(u - E[i], v)
        g[i] = (lp - lm) / (2 * h[i])
        H[i, i] = (lp - 2 * ll0 + lm) / h[i] ** 2
        dtheta[:, i] = (tp - tm) / (2 * h[i])
        for j in range(i):
            cross = (f(u + E[i] + E[j], v)[0] - f(u + E[i] - E[j], v)[0]
                     - f(u - E[i] + E[j], v)[0] + f(u - E[i] - E[j], v)[0])
            H[i, j] = H[j, i] = cross / (4 * h[i] * h[j])
    gv = hv = 0.0
    if fit_noise:
        lp, lm = f(u, v + h_v)[0], f(u, v - h_v)[0]
        gv, hv = (lp - lm) / (2 * h_v), (lp - 2 * ll0 + lm) / h_v**2
    return _Derivatives(ll0, g, H, gv, hv, dtheta)


def _information(H: np.ndarray, floor: float = 1e-2) -> np.ndarray:
    """−H made positive definite (eigenvalues' magnitudes, at least ``floor``)."""
    lam, V = np.linalg.eigh(-0.5 * (H + H.T))
    return (V * np.maximum(np.abs(lam), floor)) @ V.T


def _newton(f: _Objective, u: np.ndarray, v: float, v_bounds: tuple[float, float],
            lower: np.ndarray, settings: EffectFitSettings
            ) -> tuple[np.ndarray, float, _Derivatives]:
    """Maximise ℓ from (u, v); returns the optimum and the derivatives there.

    v stops moving once it reaches a bound with the gradient pointing outward (a flight
    without process noise drives the ML noise level to the floor).
    """
    h, h_v = np.full(u.size, 0.1), 0.05
    fit_noise = True
    for iteration in range(settings.max_iterations + 1):
        fit_noise = fit_noise and v_bounds[0] < v < v_bounds[1]
        d = _derivatives(f, u, v, h, h_v, fit_noise, lower)
        info = _information(d.H)
        step = np.linalg.solve(info, d.g)
        step *= min(1.0, settings.max_step / max(np.max(np.abs(step)), 1e-300))
        step = np.maximum(u + step, lower) - u
        step_v = 0.0
        if fit_noise:
            step_v = d.gv / -d.hv if d.hv < 0.0 else math.copysign(0.5, d.gv)
            step_v = float(np.clip(np.clip(step_v, -1.0, 1.0), v_bounds[0] - v,
                                   v_bounds[1] - v))
        # Newton decrement: twice the gain a quadratic model expects from the step.
        if step @ d.g + step_v * d.gv < 0.1 or iteration == settings.max_iterations:
            return u, v, d
        # Finite-difference steps of about one σ: the curvature over the interval.
        h = np.clip(np.sqrt(np.diag(np.linalg.inv(info))), 1e-4, 0.3)
        for _ in range(6):
            if f(u + step, v + step_v)[0] > d.ll:
                u, v = u + step, v + step_v
                break
            step, step_v = 0.5 * step, 0.5 * step_v
        else:
            return u, v, d
    raise AssertionError("unreachable")


def fit_effects(
    flight: FlightData, config: VehicleConfig, effects: Sequence[ModelEffect],
    prior: ParameterEstimate, sigma: tuple[float, float], state_sigma: _StateSigma,
    settings: EffectFitSettings | None = None,
) -> EffectFit:
    """Estimate the effects' parameters (and the noise scale) by maximum likelihood.

    Parameters
    ----------
    flight : FlightData
        As logged.
    config : VehicleConfig
        The vehicle (noise densities at scale 1).
    effects : sequence of ModelEffect
        Effects to fit; their values are the starting point.
    prior, sigma, state_sigma
        As for `ParameterEKF` and `ParameterEKF.run`.
    settings : EffectFitSettings, optional

    Returns
    -------
    EffectFit
    """
    settings = settings or EffectFitSettings()
    effects = tuple(effects)
    scales = np.concatenate([fit_scales(e) for e in effects])
    sizes = [len(e.parameters) for e in effects]
    starts = np.cumsum([0, *sizes])

    def at(psi: np.ndarray) -> tuple[ModelEffect, ...]:
        return tuple(e.with_values(psi[a:b])
                     for e, a, b in zip(effects, starts, starts[1:], strict=False))

    reference: list[WrenchReference | None] = [None]
    passes = [0]

    def evaluate(u: np.ndarray, v: float) -> tuple[float, np.ndarray]:
        passes[0] += 1
        terms = model_terms(flight, at(u * scales), config, reference[0])
        run = _filter(scaled_noise(config, 10.0**v), prior, sigma, state_sigma, terms)
        return run.log_likelihood, run.estimate.value

    lower = np.concatenate([_lower_bounds(e) for e in effects]) / scales
    u = np.maximum(np.concatenate([e.values for e in effects]) / scales, lower)
    terms, run = reference_terms(flight, effects, config, prior, sigma, state_sigma,
                                 EffectFitSettings(reference_passes=1))
    if has_wrench(effects):
        reference[0] = WrenchReference(run.states, run.estimate.value)
    v_bounds = (math.log10(NOISE_SCALE_BOUNDS[0]), math.log10(NOISE_SCALE_BOUNDS[1]))
    v = 0.0
    for _ in range(max(settings.reference_passes, 1)):
        f = _Objective(evaluate)
        u, v, d = _newton(f, u, v, v_bounds, lower, settings)
        if not has_wrench(effects):
            break
        terms = model_terms(flight, at(u * scales), config, reference[0])
        run = _filter(scaled_noise(config, 10.0**v), prior, sigma, state_sigma, terms)
        if _settled(reference[0].theta, run.estimate.value, settings.theta_tolerance):
            break
        reference[0] = WrenchReference(run.states, run.estimate.value)

    psi = u * scales
    covariance = np.linalg.inv(_information(d.H)) * np.outer(scales, scales)
    sigma_psi = np.sqrt(np.diag(covariance))
    fitted = tuple(FittedEffect(e, sigma_psi[a:b], fitted=True)
                   for e, a, b in zip(at(psi), starts, starts[1:], strict=False))
    cfg = scaled_noise(config, 10.0**v)
    terms = model_terms(flight, at(psi), config, reference[0])
    run = _filter(cfg, prior, sigma, state_sigma, terms)
    return EffectFit(
        effects=fitted, covariance=covariance, theta_sensitivity=d.dtheta / scales,
        noise_scale=10.0**v, noise_at_bound=min(v - v_bounds[0], v_bounds[1] - v) < 0.05,
        config=cfg, terms=terms, run=run, evaluations=passes[0],
    )
