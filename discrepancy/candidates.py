"""The candidate library: catalogue effects as regressors or profiles of the residual.

Every candidate is a `mavsysid.vehicle.model_effects` effect; nothing here re-derives its physics.
With r(v) the residual (`ResidualProblem.residual`) with the effect at parameter values
v, a *linear* candidate contributes the columns

    A_j = −(r(s_j e_j) − r(0)) / s_j          (sensitivity, exact when r is linear in v)

so that r(0) ≈ A v (the effect explains the residual with v). The same finite
difference of the model gives the θ columns (relative step) that every regression
carries, so a candidate is never credited with what a small change of θ explains.
A *profile* candidate (motor lag, pose delay, ground effect: nonlinear in their one
parameter; rotor-speed lag, whose negative values would pass for a motor lag) is
evaluated on a grid of values, each giving a new residual.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from mavsysid.discrepancy.residuals import ResidualProblem
from mavsysid.vehicle.model_effects import EFFECTS, ModelEffect

__all__ = [
    "PROFILE_GRIDS",
    "THETA_STEP",
    "Candidate",
    "candidate_library",
    "effect_columns",
    "theta_columns",
    "theta_jacobian",
]

#: Search grids of the profile candidates (SI): each catalogue effect's `profile` range.
PROFILE_GRIDS: dict[str, np.ndarray] = {
    name: np.arange(*effect.profile) for name, effect in EFFECTS.items()
    if effect.profile is not None}


@dataclass(frozen=True)
class Candidate:
    """One candidate effect of the library.

    Attributes
    ----------
    effect : type of ModelEffect
        The catalogue class (name, title, description, parameters).
    kind : {"linear", "profile"}
        How it is fitted: regression columns, or a one-parameter profile search.
    grid : ndarray or None
        Profile grid, SI (profile candidates only).
    """

    effect: type[ModelEffect]
    kind: str
    grid: np.ndarray | None = None

    @property
    def name(self) -> str:
        return self.effect.name

    @property
    def size(self) -> int:
        """Number of parameters."""
        return len(self.effect.parameters)


def candidate_library(names: Sequence[str] | None = None) -> tuple[Candidate, ...]:
    """The candidates (every catalogue effect by default), in catalogue order."""
    chosen = list(EFFECTS) if names is None else list(names)
    return tuple(
        Candidate(EFFECTS[n], "profile", PROFILE_GRIDS[n]) if n in PROFILE_GRIDS
        else Candidate(EFFECTS[n], "linear") for n in chosen
    )


def theta_columns(problem: ResidualProblem, fixed: Sequence[ModelEffect], r0: np.ndarray
                  ) -> np.ndarray:
    """∂r/∂θ as regressors A (N, 6, 6): r(θ) ≈ r(θ̂) − A Δθ, Δθ in SI.

    Parameters
    ----------
    problem : ResidualProblem
    fixed : sequence of ModelEffect
        Effects already in the model.
    r0 : ndarray, shape (N, 6)
        The residual at θ̂ with ``fixed``.
    """
    columns = theta_jacobian(lambda theta: problem.residual(fixed, theta), problem.theta, r0)
    if problem.theta_free is None:
        return columns
    # A held entry has no column: the least squares (minimum norm) leave it unmoved.
    return columns * np.asarray(problem.theta_free, float)


def effect_columns(problem: ResidualProblem, candidate: Candidate,
                   fixed: Sequence[ModelEffect], r0: np.ndarray,
                   at: ModelEffect | None = None) -> np.ndarray:
    """Regressors of a linear candidate, shape (N, 6, P): r(v₀) − r(v₀ + Δv) ≈ A Δv, SI.

    Parameters
    ----------
    problem : ResidualProblem
    candidate : Candidate
    fixed : sequence of ModelEffect
        The other effects in the model.
    r0 : ndarray, shape (N, 6)
        The residual with ``fixed`` (and ``at``).
    at : ModelEffect, optional
        The candidate's current values v₀ (zero when not given): the columns are the
        sensitivity there, so a fit gives the increment Δv (Gauss–Newton).
    """
    cls = candidate.effect
    v0 = np.zeros(candidate.size) if at is None else np.asarray(at.values, float)
    cols = np.empty(r0.shape + (candidate.size,))
    for j, p in enumerate(cls.parameters):
        v = v0.copy()
        v[j] += p.scale
        effect = cls(**dict(zip(cls.parameter_names(), map(float, v), strict=True)))
        cols[..., j] = -(problem.residual([*fixed, effect]) - r0) / p.scale
    return cols


#: Relative step of the θ finite differences.
THETA_STEP = 1e-3


def theta_jacobian(residual: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
                   r0: np.ndarray) -> np.ndarray:
    """∂r/∂θ as regressors A (N, 6, 6): r(θ) ≈ r(θ̂) − A Δθ, Δθ in SI.

    Parameters
    ----------
    residual : callable
        θ (6,) → residual (N, 6).
    theta : ndarray, shape (6,)
        θ̂, SI.
    r0 : ndarray, shape (N, 6)
        ``residual(theta)``.
    """
    theta = np.asarray(theta, float)
    cols = np.empty(r0.shape + (6,))
    for j in range(6):
        step = THETA_STEP * (abs(theta[j]) if theta[j] != 0.0 else 1e-3)
        shifted = theta.copy()
        shifted[j] += step
        cols[..., j] = -(residual(shifted) - r0) / step
    return cols
