"""Forward selection of candidate effects on a penalised likelihood (ΔBIC), with ties.

The regression: weighted least squares of the residual r (training samples × 6 axes,
each axis divided by its noise σ) on the θ columns plus the selected effects' columns
(`estimation.candidates`). Profile candidates change r itself and are searched on their
grid. At each step every remaining candidate is scored by the BIC of the model with it
added; the best is kept if it lowers the BIC by more than ``threshold``; candidates within
``tie_margin`` of the best are reported as explaining the residual about equally.
One-at-a-time ranking against the bare model is not used: correlated regressors would
all look good (FIELD-NOTES.md).

The smoothed residual is correlated over one smoother window (D samples), so the
likelihood counts n/D effective samples (BIC_eff = Σ_axes n_eff log(RSS_a/n) + k log(6 n_eff)) and
the least-squares covariance is inflated by D: the naive white-noise statistics would be
overconfident and flag effects on clean flights.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import statsmodels.api as sm
from scipy.stats import chi2

from estimation.candidates import Candidate, effect_columns, theta_columns
from estimation.residuals import ResidualProblem
from vehicle.model_effects import ModelEffect

__all__ = [
    "CandidateScore",
    "FittedEffect",
    "SelectionResult",
    "SelectionSettings",
    "Tie",
    "fit_theta",
    "forward_select",
]

_CHI2_95 = float(chi2.ppf(0.95, 1))


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
    """

    threshold: float = 10.0
    tie_margin: float = 6.0
    max_effects: int = 4


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
    coefficients : ndarray
        Final regression coefficients [Δθ (6), linear effect parameters …].
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


class _Regression:
    """Weighted least squares on the training rows, with effective-sample statistics."""

    def __init__(self, rows: np.ndarray, weights: np.ndarray, block: int) -> None:
        self.rows = rows
        self.weights = weights
        self.block = block

    def stack(self, r: np.ndarray, cols: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        y = (r[self.rows] * self.weights).ravel()
        X = np.concatenate([c[self.rows] for c in cols], axis=-1) if cols else np.zeros(
            (len(self.rows), 6, 0))
        X = (X * self.weights[None, :, None]).reshape(y.size, -1)
        return y, X

    def fit(self, y: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-axis RSS (6,), coefficients and covariance (inflated by the block) of y ≈ X β."""
        if X.shape[1] == 0:
            return np.sum(y.reshape(-1, 6) ** 2, axis=0), np.zeros(0), np.zeros((0, 0))
        norm = np.linalg.norm(X, axis=0)
        norm[norm == 0.0] = 1.0
        Xn = X / norm
        beta_n, *_ = np.linalg.lstsq(Xn, y, rcond=None)
        e = y - Xn @ beta_n
        rss = np.sum(e.reshape(-1, 6) ** 2, axis=0)
        s2 = float(rss.sum()) / max(y.size - X.shape[1], 1)
        cov_n = np.linalg.pinv(Xn.T @ Xn) * s2 * self.block
        return rss, beta_n / norm, cov_n / np.outer(norm, norm)

    def bic(self, rss: np.ndarray, k: int) -> float:
        """Effective BIC with one noise variance per axis, concentrated out.

        −2 log L = Σ_a n_eff log(RSS_a / n) (+ const), n the rows per axis and
        n_eff = n / D; penalty k log(6 n_eff). The per-axis variances make the criterion
        independent of the weights, which only steer the coefficient estimates.
        """
        return self.deviance(rss) + self.penalty(k)

    def penalty(self, k: int) -> float:
        """BIC penalty of k parameters: k log(6 n_eff)."""
        return float(k * np.log(6 * len(self.rows) / self.block))

    def deviance(self, rss: np.ndarray) -> float:
        """−2 log L (up to a constant) over the effective samples, per-axis variances."""
        n = len(self.rows)
        return float(n / self.block * np.sum(np.log(np.asarray(rss) / n)))


def fit_theta(problem: ResidualProblem, rows: np.ndarray, fixed: Sequence[ModelEffect] = (),
              iterations: int = 4) -> tuple[ResidualProblem, np.ndarray]:
    """Gauss–Newton equation-error fit of θ on the training rows (effects ``fixed``).

    Returns the problem at the fitted θ and the axis weights 1/σ (σ the RMS of each
    axis's final residual).
    """
    weights = np.ones(6)
    for _ in range(iterations):
        r0 = problem.residual(fixed)
        weights = 1.0 / np.maximum(np.sqrt(np.mean(r0[rows] ** 2, axis=0)), 1e-9)
        reg = _Regression(rows, weights, 1)
        _, beta, _ = reg.fit(*reg.stack(r0, [theta_columns(problem, fixed, r0)]))
        theta = problem.theta + beta
        if np.any(theta[3:] <= 0.0) or theta[0] <= 0.0:
            break  # a step to an unphysical θ: keep the last physical one
        problem = replace(problem, theta=theta)
        if np.all(np.abs(beta) <= 1e-6 * np.abs(theta) + 1e-12):
            break
    r0 = problem.residual(fixed)
    weights = 1.0 / np.maximum(np.sqrt(np.mean(r0[rows] ** 2, axis=0)), 1e-9)
    return problem, weights


@dataclass
class _Design:
    fixed: list[ModelEffect]
    r0: np.ndarray
    theta: np.ndarray
    linear: dict[str, np.ndarray]


def _design(problem: ResidualProblem, fixed: list[ModelEffect],
            linear: Sequence[Candidate]) -> _Design:
    r0 = problem.residual(fixed)
    cols = {"theta": theta_columns(problem, fixed, r0)}
    for cand in linear:
        cols[cand.name] = effect_columns(problem, cand, fixed, r0)
    return _Design(fixed, r0, cols.pop("theta"), cols)


def _profile(problem: ResidualProblem, reg: _Regression, cand: Candidate, design: _Design,
             base_cols: list[np.ndarray], grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Deviance over ``grid`` of a profile candidate, the other columns re-fitted at each value."""
    dev = np.empty(grid.size)
    for i, v in enumerate(grid):
        r = problem.residual([*design.fixed, cand.effect(**{cand.effect.parameters[0].name: v})])
        dev[i] = reg.deviance(reg.fit(*reg.stack(r, base_cols))[0])
    return grid, dev


def _refine_minimum(grid: np.ndarray, rss: np.ndarray) -> float:
    """Vertex of the parabola through the grid minimum and its neighbours."""
    i = int(np.argmin(rss))
    if i == 0 or i == grid.size - 1:
        return float(grid[i])
    x, y = grid[i - 1:i + 2], rss[i - 1:i + 2]
    a, b, _ = np.polyfit(x, y, 2)
    return float(np.clip(-b / (2 * a), x[0], x[2])) if a > 0 else float(grid[i])


def _profile_interval(grid: np.ndarray, dev: np.ndarray) -> tuple[float, float]:
    """95 % profile-likelihood interval: deviance(v) − min ≤ χ²₁(0.95)."""
    stat = dev - dev.min()
    inside = np.flatnonzero(stat <= _CHI2_95)
    lo_i, hi_i = inside.min(), inside.max()

    def cross(i: int, j: int) -> float:
        if j < 0 or j >= grid.size:
            return float(grid[i])
        # Linear interpolation of the crossing between a point inside and one outside.
        f = (_CHI2_95 - stat[i]) / (stat[j] - stat[i])
        return float(grid[i] + f * (grid[j] - grid[i]))

    return cross(lo_i, lo_i - 1), cross(hi_i, hi_i + 1)


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
    reg = _Regression(rows, weights, problem.window_samples)
    linear_all = [c for c in candidates if c.kind == "linear"]
    fixed: list[ModelEffect] = []
    chosen: list[Candidate] = []
    gains: dict[str, float] = {}
    scores: list[CandidateScore] = []
    ties: list[Tie] = []
    design = _design(problem, fixed, linear_all)
    rss0, _, _ = reg.fit(*reg.stack(design.r0, [design.theta]))
    bic_before = current = reg.bic(rss0, 6)
    for step in range(settings.max_effects):
        base_cols = [design.theta] + [design.linear[c.name] for c in chosen if c.kind == "linear"]
        k = sum(c.shape[-1] for c in base_cols)
        trial: dict[str, tuple[float, np.ndarray]] = {}
        for cand in candidates:
            if any(c.name == cand.name for c in chosen):
                continue
            if cand.kind == "linear":
                cols = [*base_cols, design.linear[cand.name]]
                rss, beta, _ = reg.fit(*reg.stack(design.r0, cols))
                trial[cand.name] = (reg.bic(rss, k + cand.size) - current, beta[k:])
            else:
                grid, rss = _profile(problem, reg, cand, design, base_cols, cand.grid)
                v = _refine_minimum(grid, rss)
                _, r_best = _profile(problem, reg, cand, design, base_cols, np.array([v]))
                if r_best[0] > rss.min():
                    v = float(grid[int(np.argmin(rss))])
                dev = min(r_best[0], rss.min())
                trial[cand.name] = (dev + reg.penalty(k + 1) - current, np.array([v]))
        for name, (d, values) in trial.items():
            scores.append(CandidateScore(step, name, float(d), values))
        best = min(trial, key=lambda name: trial[name][0])
        if trial[best][0] > -settings.threshold:
            break
        close = [(name, trial[name][0] - trial[best][0]) for name in trial
                 if name != best and trial[name][0] < -settings.threshold
                 and trial[name][0] - trial[best][0] < settings.tie_margin]
        if close:
            ties.append(Tie(step, best, tuple(c[0] for c in close),
                            tuple(float(c[1]) for c in close)))
        cand = next(c for c in candidates if c.name == best)
        chosen.append(cand)
        gains[best] = float(trial[best][0])
        if progress is not None:
            progress(f"step {step + 1}: {best} (ΔBIC {trial[best][0]:.1f})")
        if cand.kind == "profile":
            fixed.append(cand.effect(**{cand.effect.parameters[0].name: float(trial[best][1][0])}))
            design = _design(problem, fixed, linear_all)
        current += trial[best][0]
    return _final_fit(problem, reg, chosen, fixed, gains, scores, ties, bic_before)


def _final_fit(problem: ResidualProblem, reg: _Regression, chosen: list[Candidate],
               fixed: list[ModelEffect], gains: dict[str, float], scores: list[CandidateScore],
               ties: list[Tie], bic_before: float) -> SelectionResult:
    """Joint fit of θ and the chosen effects; intervals; likelihood-ratio p-values."""
    linear = [c for c in chosen if c.kind == "linear"]
    # Re-profile each nonlinear effect with everything else in place (one pass).
    for i, eff in enumerate(fixed):
        cand = next(c for c in chosen if c.name == eff.name)
        others = fixed[:i] + fixed[i + 1:]
        design = _design(problem, others, linear)
        cols = [design.theta] + [design.linear[c.name] for c in linear]
        grid, rss = _profile(problem, reg, cand, design, cols, cand.grid)
        fixed[i] = cand.effect(**{cand.effect.parameters[0].name: _refine_minimum(grid, rss)})
    design = _design(problem, fixed, linear)
    cols = [design.theta] + [design.linear[c.name] for c in linear]
    y, X = reg.stack(design.r0, cols)
    norm = np.linalg.norm(X, axis=0)
    ols = sm.OLS(y, X / norm).fit()
    beta = ols.params / norm
    rss = np.sum((y - X @ beta).reshape(-1, 6) ** 2, axis=0)
    # statsmodels' covariance assumes white rows; the block inflation makes it honest.
    cov = ols.cov_params() * reg.block / np.outer(norm, norm)
    k = X.shape[1] + len(fixed)
    bic_after = reg.bic(rss, k) if chosen else bic_before
    fitted: dict[str, FittedEffect] = {}
    offset = 6
    for cand in linear:
        P = cand.size
        values = beta[offset:offset + P]
        sigma = np.sqrt(np.diag(cov)[offset:offset + P])
        without = [c for j, c in enumerate(cols) if j != 1 + linear.index(cand)]
        rss_without = reg.fit(*reg.stack(design.r0, without))[0]
        fitted[cand.name] = FittedEffect(
            cand.effect(**dict(zip(cand.effect.parameter_names(), map(float, values),
                                   strict=True))),
            sigma, np.column_stack([values - 1.96 * sigma, values + 1.96 * sigma]),
            gains[cand.name], _lr_p(reg.deviance(rss_without) - reg.deviance(rss), P), "linear")
        offset += P
    for i, eff in enumerate(fixed):
        cand = next(c for c in chosen if c.name == eff.name)
        others = fixed[:i] + fixed[i + 1:]
        d = _design(problem, others, linear)
        c_cols = [d.theta] + [d.linear[c.name] for c in linear]
        v = float(eff.values[0])
        grid = np.union1d(cand.grid, np.linspace(max(v - 0.015, 0.0), v + 0.015, 25))
        grid, prss = _profile(problem, reg, cand, d, c_cols, grid)
        lo, hi = _profile_interval(grid, prss)
        if cand.effect.parameters[0].unit == "s":
            # Rotor speeds and poses are stamped to within a sample interval of each other
            # (ESC telemetry carries no time stamp, FIELD-NOTES.md); a time-like parameter
            # cannot be resolved better: uniform ±dt/2, σ = dt/√12, in quadrature.
            extra = 1.96 * problem.dt / np.sqrt(12.0)
            lo = v - float(np.hypot(v - lo, extra))
            hi = v + float(np.hypot(hi - v, extra))
        fitted[cand.name] = FittedEffect(
            eff, np.array([(hi - lo) / (2 * 1.96)]), np.array([[lo, hi]]), gains[cand.name],
            _lr_p(float(prss[np.argmin(np.abs(grid))] - prss.min()), 1), "profile")
    ordered = tuple(fitted[c.name] for c in chosen)
    return SelectionResult(
        effects=ordered, ties=tuple(ties), scores=tuple(scores),
        theta_before=problem.theta.copy(), theta_after=problem.theta + beta[:6],
        bic_before=float(bic_before), bic_after=float(bic_after), weights=reg.weights,
        block=reg.block,
    )


def _lr_p(deviance_drop: float, dof: int) -> float:
    """p-value of the likelihood-ratio statistic (the deviance drop) against χ²(dof)."""
    return float(chi2.sf(max(deviance_drop, 0.0), dof))
