"""Forward selection of candidate effects on a penalised likelihood (ΔBIC), with ties.

The regression: weighted least squares of the residual r (training samples × 6 axes,
each axis divided by its noise σ) on the θ columns plus the selected effects' columns
(`mavsysid.discrepancy.candidates`). Profile candidates change r itself and are searched on their
grid. At each step every remaining candidate is scored by the BIC of the model with it
added; the best is kept if it lowers the BIC by more than ``threshold``; candidates within
``tie_margin`` of the best are reported as explaining the residual about equally.
One-at-a-time ranking against the bare model is not used: correlated regressors would
all look good (on a residual with two hidden drag terms it also named ground effect and a
thrust scale, where forward selection named exactly the two).

The statistics (effective samples, per-axis variances, block-inflated covariance) are
`mavsysid.discrepancy.regression`'s: BIC_eff = Σ_axes n_eff log(RSS_a / n) + k log(6 n_eff).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import statsmodels.api as sm
from mavsysid.discrepancy.candidates import Candidate
from mavsysid.discrepancy.regression import Regression, lr_p, profile_interval, refine_minimum
from mavsysid.discrepancy.residuals import ResidualProblem
from mavsysid.discrepancy.selection_model import SelectionModel
from mavsysid.vehicle.config_schema import EFFECT_PARAMETER_SIGNS
from mavsysid.vehicle.model_effects import ModelEffect
from scipy.stats import chi2

__all__ = [
    "CandidateScore",
    "FittedEffect",
    "SelectionResult",
    "SelectionSettings",
    "Tie",
    "forward_select",
]


@dataclass(frozen=True)
class SelectionSettings:
    """Choices of the forward selection.

    Attributes
    ----------
    threshold : float
        ΔBIC an effect must gain to be kept (10: "very strong" evidence, Kass & Raftery).
    tie_margin : float
        Candidates whose BIC is within this of the best one's are a tie.
    max_effects : int
        Most effects named.
    wald_p : float
        A linear candidate must also pass the joint Wald test of its parameters being
        zero at this level (block-inflated covariance: the one behind the reported CIs).
    """

    threshold: float = 10.0
    tie_margin: float = 6.0
    max_effects: int = 4
    wald_p: float = 1e-3


@dataclass(frozen=True)
class CandidateScore:
    """A candidate's score at one selection step.

    Attributes
    ----------
    step : int
        0 for the first effect, 1 for the second, …
    name : str
    delta_bic : float
        BIC with the candidate added minus the BIC of the step's current model.
    values : ndarray, shape (P,)
        Its best-fitting parameter values, SI.
    """

    step: int
    name: str
    delta_bic: float
    values: np.ndarray


@dataclass(frozen=True)
class FittedEffect:
    """A selected effect with its fitted parameters.

    Attributes
    ----------
    effect : ModelEffect
        The catalogue effect at its fitted values.
    sigma : ndarray, shape (P,)
        Standard error, SI (for a profile: half the 95 % interval / 1.96).
    ci95 : ndarray, shape (P, 2)
        95 % confidence interval, SI.
    delta_bic : float
        The BIC gained when it was selected (negative).
    p_value : float
        Likelihood-ratio test of the final model against it removed.
    kind : {"linear", "profile"}
    """

    effect: ModelEffect
    sigma: np.ndarray
    ci95: np.ndarray
    delta_bic: float
    p_value: float
    kind: str


@dataclass(frozen=True)
class Tie:
    """Candidates that explain the residual about equally at one step."""

    step: int
    chosen: str
    alternatives: tuple[str, ...]
    delta_bic_gap: tuple[float, ...]


@dataclass(frozen=True)
class SelectionResult:
    """What the forward selection found.

    Attributes
    ----------
    effects : tuple of FittedEffect
        Most important first; empty when nothing is significant.
    ties : tuple of Tie
    scores : tuple of CandidateScore
        Every candidate at every step.
    theta_before, theta_after : ndarray, shape (6,)
        θ fitted without and with the selected effects, SI.
    bic_before, bic_after : float
        Effective BIC of the base and the final model (training data).
    weights : ndarray, shape (6,)
        1/σ of each axis used in the regression.
    block : int
        Effective-sample block D (smoother window, samples).
    theta_after_sigma : ndarray, shape (6,) or None
        Standard error of ``theta_after`` from the final regression (block-inflated, so
        it includes the collinearity of θ with the named effects), SI; None when no
        effect was named.
    """

    effects: tuple[FittedEffect, ...]
    ties: tuple[Tie, ...]
    scores: tuple[CandidateScore, ...]
    theta_before: np.ndarray
    theta_after: np.ndarray
    bic_before: float
    bic_after: float
    weights: np.ndarray
    block: int
    theta_after_sigma: np.ndarray | None = None


def forward_select(
    problem: ResidualProblem, candidates: Sequence[Candidate], rows: np.ndarray,
    weights: np.ndarray, settings: SelectionSettings | None = None,
    progress: Callable[[str], None] | None = None,
) -> SelectionResult:
    """Forward selection of ``candidates`` explaining the residual of ``problem``.

    Parameters
    ----------
    problem : ResidualProblem
        At the base θ (`fit_theta`).
    candidates : sequence of Candidate
    rows : ndarray of int
        Training sample indices.
    weights : ndarray, shape (6,)
        1/σ per axis.
    settings : SelectionSettings, optional
    progress : callable, optional
        Called with a short message at each step.

    Returns
    -------
    SelectionResult
    """
    settings = settings or SelectionSettings()
    reg = Regression(rows, weights, problem.block)
    model = SelectionModel(problem, candidates)
    theta_base = problem.theta.copy()
    gains: dict[str, float] = {}
    scores: list[CandidateScore] = []
    ties: list[Tie] = []
    r0, cols, extra = model.design(candidates)
    bic_before = current = reg.bic(reg.fit(*reg.stack(r0, cols))[0], 6)
    for step in range(settings.max_effects):
        remaining = [c for c in candidates if c.name not in {e.name for e in model.effects}]
        if progress is not None:
            progress(f"step {step + 1}: scoring {len(remaining)} candidate effects")
        if step > 0:
            r0, cols, extra = model.design(remaining)
        trial, weak = _score_candidates(model, reg, remaining, (r0, cols, extra), current,
                                        settings.wald_p)
        for name, (d, values) in trial.items():
            scores.append(CandidateScore(step, name, float(d), values))
        if not trial:
            break
        eligible = [name for name in trial if name not in weak]
        if not eligible:
            break
        best = min(eligible, key=lambda name: trial[name][0])
        if trial[best][0] > -settings.threshold:
            break
        close = [(name, trial[name][0] - trial[best][0]) for name in eligible
                 if name != best and trial[name][0] < -settings.threshold
                 and trial[name][0] - trial[best][0] < settings.tie_margin]
        if close:
            ties.append(Tie(step, best, tuple(c[0] for c in close),
                            tuple(float(c[1]) for c in close)))
        cand = model.candidate(best)
        values = trial[best][1]
        model.effects.append(cand.effect(**dict(zip(cand.effect.parameter_names(),
                                                    map(float, values), strict=True))))
        gains[best] = float(trial[best][0])
        if progress is not None:
            progress(f"step {step + 1}: {best} (ΔBIC {trial[best][0]:.1f})")
        # Re-linearise at the joint optimum: the columns (and the effects' wrenches, which
        # scale with c_T and c_D) depend on θ and on the effects' values, and a θ distorted
        # by the unmodelled effect would leave an error for the next step to "explain".
        model.relinearise(reg)
        r_cur, cols_cur, _ = model.design()
        current = reg.bic(reg.fit(*reg.stack(r_cur, cols_cur))[0], model.k())
    return _final_fit(model, reg, gains, scores, ties, bic_before, theta_base)


def _score_candidates(
    model: SelectionModel, reg: Regression, remaining: Sequence[Candidate],
    design: tuple[np.ndarray, list[np.ndarray], dict[str, np.ndarray]], current: float,
    wald_p: float,
) -> tuple[dict[str, tuple[float, np.ndarray]], set[str]]:
    """Each remaining candidate's ΔBIC against the current model and best values.

    Parameters
    ----------
    design : tuple
        ``model.design(remaining)``: r0 (N, 6), the current columns, candidate columns.
    current : float
        BIC of the current model.
    wald_p : float
        Level of the Wald test a linear candidate must pass.

    Returns
    -------
    trial : dict
        ``{name: (ΔBIC, values (P,))}``.
    weak : set of str
        Linear candidates whose parameters are not jointly distinguishable from zero, or
        break a sign their physics has (`EFFECT_PARAMETER_SIGNS`).
    """
    r0, cols, extra = design
    k = model.k()
    trial: dict[str, tuple[float, np.ndarray]] = {}
    weak: set[str] = set()
    for cand in remaining:
        if cand.kind == "linear":
            rss, beta, cov = reg.fit(*reg.stack(r0, [*cols, extra[cand.name]]))
            b, c = beta[-cand.size:], cov[-cand.size:, -cand.size:]
            trial[cand.name] = (reg.bic(rss, k + cand.size) - current, b)
            # The BIC counts the effective samples but not the systematic leftovers of
            # the effects already named; the Wald test on the block-inflated covariance
            # (the reported CIs) must agree, or the effect is not named.
            wald = float(b @ np.linalg.solve(c, b))
            if chi2.sf(wald, cand.size) > wald_p or _wrong_sign(cand, b):
                weak.add(cand.name)
        else:
            dev = model.profile(reg, cand, cand.grid, cols, model.effects)
            v = refine_minimum(cand.grid, dev)
            dev_v = model.profile(reg, cand, np.array([v]), cols, model.effects)[0]
            if dev_v > dev.min():
                v, dev_v = float(cand.grid[int(np.argmin(dev))]), float(dev.min())
            trial[cand.name] = (dev_v + reg.penalty(k + 1) - current, np.array([v]))
    return trial, weak


def _wrong_sign(candidate: Candidate, values: np.ndarray) -> bool:
    """Whether ``values`` break a sign the effect's physics has (a drag or an inertia < 0).

    Such a fit is a shape of the residual, not the effect: a negative rotor inertia is a
    lag of the yaw response, what a late pose gives.
    """
    for p, v in zip(candidate.effect.parameters, values, strict=True):
        sign = EFFECT_PARAMETER_SIGNS.get((candidate.name, p.name))
        if sign is not None and v < 0.0:
            return True
    return False


def _final_fit(model: SelectionModel, reg: Regression, gains: dict[str, float],
               scores: list[CandidateScore], ties: list[Tie], bic_before: float,
               theta_base: np.ndarray) -> SelectionResult:
    """Joint fit of θ and the chosen effects; intervals; likelihood-ratio p-values."""
    if not model.effects:
        return SelectionResult((), tuple(ties), tuple(scores), theta_base, theta_base.copy(),
                               float(bic_before), float(bic_before), reg.weights, reg.block)
    profiles = [i for i, e in enumerate(model.effects) if model.library[e.name].kind == "profile"]
    # Re-profile each nonlinear effect with everything else in place (one pass).
    for i in profiles:
        e = model.effects[i]
        cand = model.library[e.name]
        others = [o for j, o in enumerate(model.effects) if j != i]
        _, cols, _ = model.design()
        dev = model.profile(reg, cand, cand.grid, cols, others)
        model.effects[i] = e.with_values(np.array([refine_minimum(cand.grid, dev)]))
    model.relinearise(reg)
    r0, cols, _ = model.design()
    y, X = reg.stack(r0, cols)
    norm = np.linalg.norm(X, axis=0)
    live = norm > 0.0  # a θ entry held fixed has no column: it stays, with σ 0
    norm[~live] = 1.0
    ols = sm.OLS(y, X[:, live] / norm[live]).fit()
    beta = np.zeros(X.shape[1])
    beta[live] = ols.params / norm[live]
    rss = np.sum((y - X @ beta).reshape(-1, 6) ** 2, axis=0)
    # statsmodels' covariance assumes white rows; the block inflation makes it honest.
    cov = np.zeros((X.shape[1], X.shape[1]))
    cov[np.ix_(live, live)] = ols.cov_params() * reg.block / np.outer(norm[live], norm[live])
    dev_full = reg.deviance(rss)
    fitted: dict[str, FittedEffect] = {}
    offset = 6
    for col_index, e in enumerate(model.linear, start=1):
        P = len(e.values)
        values = e.values + beta[offset:offset + P]
        sigma = np.sqrt(np.diag(cov)[offset:offset + P])
        others = [o for o in model.effects if o is not e]
        r_without = model.problem.residual(others)
        without = [c for j, c in enumerate(cols) if j != col_index]
        dev_without = reg.deviance(reg.fit(*reg.stack(r_without, without))[0])
        fitted[e.name] = FittedEffect(
            e.with_values(values), sigma,
            np.column_stack([values - 1.96 * sigma, values + 1.96 * sigma]),
            gains[e.name], lr_p(dev_without - dev_full, P), "linear")
        offset += P
    for i in profiles:
        e = model.effects[i]
        cand = model.library[e.name]
        others = [o for j, o in enumerate(model.effects) if j != i]
        v = float(e.values[0])
        grid = np.union1d(cand.grid, np.linspace(max(v - 0.015, 0.0), v + 0.015, 25))
        dev = model.profile(reg, cand, grid, cols, others)
        lo, hi = profile_interval(grid, dev)
        if cand.effect.parameters[0].unit == "s":
            # Rotor speeds and poses are stamped to within a sample interval of each other
            # (MAVLink's ESC_TELEMETRY_* messages carry no time stamp and are stamped on
            # receipt); a time-like parameter cannot be resolved better: uniform ±dt/2,
            # σ = dt/√12, in quadrature.
            extra = 1.96 * model.problem.stamp_dt / np.sqrt(12.0)
            lo = v - float(np.hypot(v - lo, extra))
            hi = v + float(np.hypot(hi - v, extra))
        fitted[e.name] = FittedEffect(
            e, np.array([(hi - lo) / (2 * 1.96)]), np.array([[lo, hi]]), gains[e.name],
            lr_p(float(dev[np.argmin(np.abs(grid))] - dev.min()), 1), "profile")
    ordered = tuple(fitted[e.name] for e in model.effects)
    return SelectionResult(
        effects=ordered, ties=tuple(ties), scores=tuple(scores),
        theta_before=theta_base, theta_after=model.problem.theta + beta[:6],
        bic_before=float(bic_before), bic_after=float(reg.bic(rss, model.k())),
        weights=reg.weights, block=reg.block,
        theta_after_sigma=np.sqrt(np.diag(np.asarray(cov))[:6]),
    )
