"""What the filter fits by maximum likelihood besides θ: the process-noise level and the
parameters of known model effects, and the effects in the filter's terms.

**Effects in the filter's terms** (`model_terms`). A `ModelEffect` enters through up to
three channels: ``rotor_speeds`` (the filter is driven by the acting speeds),
``pose`` (the poses are corrected; a delay re-times them, each pose then paired with the
acting rotor speeds interpolated at its corrected time, so the sample count stays the
same for every delay) and ``wrench`` (an extra body force and torque per sample, linear
between samples in the filter's RK4 step). The wrench depends on the state and θ but is
defined in numpy, once for truth and model, so it is evaluated on a previous filter pass
(`WrenchReference`); `reference_terms` iterates the passes until θ settles.

**The noise level** (`fit_noise_scale`). The force and moment noise densities of the
vehicle config are assumptions; the filter's innovation log-likelihood
Σ log N(y_k; 0, S_k) is a function of their scale, and its maximum is the
maximum-likelihood noise level (the classical way to tune a Kalman filter from data). Too
much noise throws information away; too little makes the filter overconfident. A fit at
the upper edge of its range is refused.

**Effects' parameters** (`fit_effect_parameters`). ψ is estimated from the same flight as
θ: ℓ(ψ, s) is the marginal likelihood of the poses given ψ and the noise scale s, θ and
the states integrated out by the filter; its maximum is the joint ML estimate, and σ(ψ)
comes from the observed information −∂²ℓ/∂ψ² (central differences at about one σ). Signed
parameters are kept in their range. Through the likelihood rather than an augmented filter
state because the effects act through channels that are not smooth inside the filter (a
delay re-times the measurements, a motor lag filters the whole rotor-speed log). A damped
Newton method in scaled units; the ψ–s cross terms are taken as zero (parameters of the
mean and of the covariance are asymptotically orthogonal). ψ's uncertainty is carried
into θ's: Σ_θ ← Σ_θ|ψ + J Σ_ψ Jᵀ (`EffectFit.theta_covariance_increment`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from mavsysid.estimation.filter.ekf import FilterRun, ParameterEKF
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import FittedEffect, ParameterEstimate
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.config_schema import EFFECT_PARAMETER_SIGNS
from mavsysid.vehicle.linearization import MEAS_DIM
from mavsysid.vehicle.model_effects import EffectInputs, ModelEffect, total_wrench

from mavsysid.errors import JobFailedError

__all__ = ["NOISE_SCALE_BOUNDS", "NOISE_SCALE_LIMITS", "NOISE_SCALE_TOLERANCE", "EffectFit",
           "EffectFitSettings", "ModelTerms", "NoiseFit", "WrenchReference",
           "fit_effect_parameters", "fit_noise_scale", "fit_scales", "has_wrench",
           "in_model_terms", "maximise_log_scale", "model_terms", "reference_terms",
           "scaled_noise"]


#: Range of the noise scale searched first.
NOISE_SCALE_BOUNDS = (1e-3, 30.0)

#: How far the search extends beyond `NOISE_SCALE_BOUNDS` when the maximum lies at one of
#: its edges (real flights of small vehicles have needed ≈ 30×); a maximum at the edge of
#: these limits is reported as ``at_bound``.
NOISE_SCALE_LIMITS = (1e-4, 1e3)



@dataclass(frozen=True)
class NoiseFit:
    """The fitted noise scale and the filter run at that scale.

    Attributes
    ----------
    scale : float
        Factor applied to both the force and the moment noise densities of the config.
    config : VehicleConfig
        The config with the scaled densities.
    run : FilterRun
        The filter over the flight at the fitted scale.
    at_bound : bool
        The maximum lies at the edge of the search range (extended to ``limits``).
    at_upper_bound : bool
        ... at its upper edge: more unmodelled force than the range allows.
    """

    scale: float
    config: VehicleConfig
    run: FilterRun
    at_bound: bool
    at_upper_bound: bool = False


def scaled_noise(config: VehicleConfig, scale: float) -> VehicleConfig:
    """The config with its force and moment noise densities multiplied by ``scale``."""
    nz = config.noise
    return replace(config, noise=replace(nz, force_density=nz.force_density * scale,
                                         moment_density=nz.moment_density * scale))


#: Tolerance of the fitted noise scale, decades of the scale.
NOISE_SCALE_TOLERANCE = 0.01

# The search's first step and its growth while the likelihood rises, decades; a maximum
# within `_EDGE` decades of an edge of the range is at it; a parabola's vertex is trusted
# to the tolerance within a bracket `_NARROW` decades wide.
_FIRST_STEP, _GROWTH, _EDGE, _NARROW = 0.3, 2.5, 0.05, 0.3


def _vertex(x: tuple[float, float, float], f: tuple[float, float, float]) -> float | None:
    """log10 s of the extremum of the parabola through three points (x = log10 s) in
    u = s^(−1/2); None if it has none.

    The innovation likelihood is far from symmetric in log s (a steep wall at small
    noise) and closer to a parabola in s^(−1/2), the scale of the filter's gain.
    """
    a, b, c = (10.0 ** (-0.5 * v) for v in x)
    fa, fb, fc = f
    p, q = (b - a) * (fb - fc), (b - c) * (fb - fa)
    den = 2.0 * (p - q)
    if not (math.isfinite(p) and math.isfinite(q)) or den == 0.0:
        return None
    u = b - ((b - a) * p - (b - c) * q) / den
    return -2.0 * math.log10(u) if u > 0.0 else None


def _uphill(f: Callable[[float], float], x0: float, edges: tuple[float, float],
            direction: float) -> tuple[float, float, float] | None:
    """Walk from x0 while f rises, each step longer than the last.

    Returns a bracket (a, b, c), a < b < c, f(b) ≥ f(a), f(c); (e, e, e) for a maximum
    within `_EDGE` of the edge e; None if the first step falls.
    """
    prev, cur, step = None, x0, _FIRST_STEP
    for _ in range(64):
        edge = edges[1] if direction > 0 else edges[0]
        if cur == edge:
            inner = cur - direction * _EDGE
            if f(inner) <= f(cur):
                return cur, cur, cur
            if prev is not None and direction * (inner - prev) > 0.0:
                a, b, c = sorted((prev, inner, cur))
                return a, b, c
            # The maximum is inward of `inner`: walk back, the edge the lower point behind.
            prev, cur, step, direction = cur, inner, _FIRST_STEP, -direction
            continue
        nxt = cur + direction * step
        if direction * (edge - nxt) < _FIRST_STEP:
            nxt = edge
        if f(nxt) <= f(cur):
            if prev is None:
                return None
            a, b, c = sorted((prev, cur, nxt))
            return a, b, c
        prev, cur, step = cur, nxt, step * _GROWTH
    raise AssertionError("unreachable: the steps grow until an edge")


def maximise_log_scale(f: Callable[[float], float], x0: float,
                       edges: tuple[float, float], rising: bool) -> float:
    """The maximum of a unimodal f over [edges] to `NOISE_SCALE_TOLERANCE`, from x0.

    A bracket from walking uphill (first the way ``rising`` says), then parabolas through
    the bracket (`_vertex`; golden sections where a parabola points outside it or leaves
    it lopsided) until the next vertex lies within the tolerance of the best point of a
    bracket at most `_NARROW` wide.

    Parameters
    ----------
    f : callable
        log10 s → the log-likelihood (−inf where it cannot be evaluated); called once per
        point.
    x0 : float
        Start, log10 s, within ``edges``.
    edges : tuple of 2 float
        The range searched, log10 s; a maximum within `_EDGE` of an edge is returned as
        that edge.
    rising : bool
        Step up first (else down).

    Returns
    -------
    float
        log10 s of the best point evaluated.
    """
    values: dict[float, float] = {}

    def cached(x: float) -> float:
        if x not in values:
            values[x] = f(x)
        return values[x]

    direction = 1.0 if rising else -1.0
    bracket = (_uphill(cached, x0, edges, direction)
               or _uphill(cached, x0, edges, -direction))
    if bracket is None:  # falls at the first step both ways: x0 between those steps
        bracket = (max(x for x in values if x < x0), x0, min(x for x in values if x > x0))
    a, b, c = bracket
    tol = NOISE_SCALE_TOLERANCE
    for _ in range(64):
        if c - a <= 2.0 * tol:
            break
        x = _vertex((a, b, c), (cached(a), cached(b), cached(c)))
        near, far = sorted((b - a, c - b))
        far_side = 1.0 if c - b > b - a else -1.0
        if x is None or not a < x < c or (far > 0.5 * _NARROW and far > 3.0 * near):
            # No parabola, or one that leaves a lopsided bracket as wide: golden section.
            x = b + 0.381966 * far * far_side
        elif abs(x - b) < tol:
            if far <= 0.5 * _NARROW:
                break
            x = b + 0.3 * _NARROW * far_side  # a bracket too wide to trust its parabola
        if cached(x) > cached(b):
            a, b, c = (a, x, b) if x < b else (b, x, c)
        elif x < b:
            a = x
        else:
            c = x
    return b


def fit_noise_scale(
    flight: FlightData, config: VehicleConfig, prior: ParameterEstimate,
    sigma: tuple[float, float], state_sigma: tuple[float, float, float, float],
    bounds: tuple[float, float] = NOISE_SCALE_BOUNDS, wrench: np.ndarray | None = None,
    limits: tuple[float, float] = NOISE_SCALE_LIMITS, unit_run: FilterRun | None = None,
) -> NoiseFit:
    """Maximise the innovation likelihood over one common noise scale (log-space search).

    Parameters
    ----------
    flight, config, prior, sigma, state_sigma, wrench
        As for `ParameterEKF` and `ParameterEKF.run` (``flight`` and ``wrench`` in the
        model's terms when there are known effects, `mavsysid.estimation.filter.likelihood`).
    bounds : tuple of 2 float
        Range of the scale searched first.
    limits : tuple of 2 float
        A maximum at the upper edge of ``bounds`` is searched for again between that edge
        and the upper limit; the lower limit is not searched.
    unit_run : FilterRun, optional
        The filter already run with exactly these arguments at scale 1 (the configured
        densities): the search starts there without running it again.

    Notes
    -----
    Each filter pass is the cost of the fit (≈ 0.5 s of CPU per 30 000 samples), so the
    search spends few (`maximise_log_scale`): from scale 1 (or the range's nearest edge)
    it steps a third of a decade the way the innovations ask (a mean NIS above the
    measurement dimension asks for more noise), lengthens its steps until the likelihood
    falls, then interpolates parabolas to `NOISE_SCALE_TOLERANCE` decades: 3 to 6 passes
    besides ``unit_run`` on simulated flights with wind, motor lag, pose delay or process
    noise, 4 with the maximum at the lower edge. The likelihood's curvature puts the
    scale's own standard error near 0.01 decades on a 30 s flight at 100 Hz; over that the
    refined θ moves by < 0.01 σ and its σ by ≈ 2 %.
    """
    runs: dict[float, FilterRun] = {}
    if unit_run is not None:
        runs[0.0] = unit_run

    def run_at(log_scale: float) -> FilterRun:
        if log_scale not in runs:
            cfg = scaled_noise(config, 10.0**log_scale)
            runs[log_scale] = ParameterEKF(cfg, prior, sigma).run(flight, state_sigma, wrench)
        return runs[log_scale]

    def log_likelihood(log_scale: float) -> float:
        try:
            return run_at(log_scale).log_likelihood
        except JobFailedError:
            return -math.inf  # a level at which the filter overflows is no maximum

    lo, hi = math.log10(bounds[0]), math.log10(bounds[1])
    # For a unimodal likelihood, searching up to the upper limit is the same as searching
    # ``bounds`` and then beyond a maximum at their upper edge; the lower limit is not
    # searched: a maximum there means the model fits better than the configured densities
    # assume (a noise-free simulation does).
    far_hi = max(hi, math.log10(limits[1]))
    x0 = min(max(0.0, lo), hi)
    try:  # a mean NIS above the measurement dimension asks for more noise
        rising = bool(np.nanmean(run_at(x0).history.nis) > MEAS_DIM)
    except JobFailedError:
        rising = False
    x = maximise_log_scale(log_likelihood, x0, (lo, far_hi), rising)
    at_bound = bool(min(x - lo, far_hi - x) < 0.05)
    scale = 10.0 ** x
    return NoiseFit(scale, scaled_noise(config, scale), run_at(x), at_bound,
                    bool(far_hi - x < 0.05))


@dataclass(frozen=True)
class WrenchReference:
    """Where state-dependent effect wrenches are evaluated: a previous filter pass.

    Attributes
    ----------
    states : ndarray, shape (N, 13)
        Filtered model states [p, v_B, q, ω] at every sample.
    theta : ndarray, shape (6,)
        θ of that pass (its final estimate), SI.
    """

    states: np.ndarray
    theta: np.ndarray


@dataclass(frozen=True)
class ModelTerms:
    """A flight in the model's terms under some effects.

    Attributes
    ----------
    flight : FlightData
        Corrected times and poses, acting rotor speeds (N samples, as the log).
    wrench : ndarray, shape (N, 6)
        Extra body force (N) and torque (N·m) per sample; zeros without wrench effects.
    effects : tuple of ModelEffect
        The effects applied, with their values.
    """

    flight: FlightData
    wrench: np.ndarray
    effects: tuple[ModelEffect, ...]


def has_wrench(effects: Sequence[ModelEffect]) -> bool:
    """True when any of ``effects`` adds a force or torque (needs a `WrenchReference`)."""
    return any("wrench" in e.channels for e in effects)


def in_model_terms(flight: FlightData, effects: Sequence[ModelEffect]) -> FlightData:
    """The flight with the effects' rotor-speed and pose channels applied (see module doc)."""
    t, n = flight.t, flight.rotor_speeds
    for effect in effects:
        if "rotor_speeds" in effect.channels:
            n = effect.acting_rotor_speeds(t, n)
    t_model, p, q = t, flight.position, flight.quaternion
    for effect in effects:
        if "pose" in effect.channels:
            t_model, p, q = effect.corrected_pose(t_model, p, q)
    if t_model is not t and not np.array_equal(t_model, t):
        # np.interp holds the end values outside the log: the sample count stays fixed.
        n = np.column_stack([np.interp(t_model, t, n[:, i]) for i in range(n.shape[1])])
    if n is flight.rotor_speeds and t_model is t and p is flight.position:
        return flight
    return replace(flight, t=np.asarray(t_model, float), position=np.asarray(p, float),
                   quaternion=np.asarray(q, float), rotor_speeds=np.asarray(n, float))


def _wrench(model_flight: FlightData, log_start: float, effects: Sequence[ModelEffect],
            config: VehicleConfig, reference: WrenchReference) -> np.ndarray:
    """The effects' wrench (N, 6) on the reference states, at the model's times."""
    x = reference.states
    if x.shape != (len(model_flight), 13):
        raise ValueError(f"reference states of shape ({len(model_flight)}, 13) expected, "
                         f"got {x.shape}")
    inputs = EffectInputs(
        t=model_flight.t - log_start, position=x[:, 0:3], quaternion=x[:, 6:10],
        velocity=x[:, 3:6], rates=x[:, 10:13], rotor_speeds=model_flight.rotor_speeds,
        theta=np.asarray(reference.theta, float),
        rotor_positions=np.asarray(config.rotor_positions, float),
        rotor_directions=np.asarray(config.rotor_directions, float))
    force, torque = total_wrench(list(effects), inputs)
    return np.ascontiguousarray(np.hstack([force, torque]))


def model_terms(
    flight: FlightData, effects: Sequence[ModelEffect], config: VehicleConfig,
    reference: WrenchReference | None = None,
) -> ModelTerms:
    """The flight and the wrench under ``effects`` (the model's view of the log).

    Parameters
    ----------
    flight : FlightData
        As logged.
    effects : sequence of ModelEffect
        Known effects with their values; empty for the paper's model.
    config : VehicleConfig
        Rotor geometry for the wrench.
    reference : WrenchReference, optional
        States and θ to evaluate wrench effects on; without one the wrench is zero (the
        first pass of `reference_terms` in `mavsysid.estimation.filter.likelihood`).

    Returns
    -------
    ModelTerms
    """
    effects = tuple(effects)
    model_flight = in_model_terms(flight, effects)
    if reference is None or not has_wrench(effects):
        wrench = np.zeros((len(flight), 6))
    else:
        wrench = _wrench(model_flight, float(flight.t[0]), effects, config, reference)
    return ModelTerms(model_flight, wrench, effects)


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
    theta_sensitivity : ndarray, shape (Q, P)
        dθ̂/dψ of the filter's final estimate of the Q quantities, SI.
    noise_scale : float
        Fitted process-noise scale (as `mavsysid.estimation.filter.likelihood`).
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
        """J Σ_ψ Jᵀ, the part of θ's covariance due to the effects' uncertainty, (Q, Q) for
        the Q estimated quantities."""
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
    dtheta: np.ndarray    # ∂θ̂/∂u (quantities, P)


def _derivatives(f: _Objective, u: np.ndarray, v: float, h: np.ndarray, h_v: float,
                 fit_noise: bool, lower: np.ndarray) -> _Derivatives:
    """Central differences of ℓ: gradient, Hessian over u (with cross terms), v block.

    A parameter within h of its lower bound is differenced about bound + h instead: the
    stencil must not leave the range where the effect is defined.
    """
    P = u.size
    u = np.maximum(u, lower + h)
    ll0, theta0 = f(u, v)
    g, H, dtheta = np.zeros(P), np.zeros((P, P)), np.zeros((theta0.size, P))
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


def fit_effect_parameters(
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
