"""The current model of the forward selection: θ and the effects chosen so far.

`mavsysid.discrepancy.selection` grows it one effect at a time; it evaluates the residual
and the regression columns with the chosen effects in place, re-linearises θ and the
linear effects' values (damped Gauss–Newton), and profiles a nonlinear candidate over its
grid.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from mavsysid.discrepancy.candidates import Candidate, effect_columns, theta_columns
from mavsysid.discrepancy.regression import Regression
from mavsysid.discrepancy.residuals import ResidualProblem
from mavsysid.vehicle.model_effects import ModelEffect

__all__ = ["SelectionModel"]


class SelectionModel:
    """The current model: θ (in the problem) and the chosen effects at their values.

    ``design`` evaluates the residual with every chosen effect in place and the columns of
    θ, of the chosen linear effects (at their values: increments) and of the candidates
    not chosen yet (at zero).
    """

    def __init__(self, problem: ResidualProblem, library: Sequence[Candidate]) -> None:
        self.problem = problem
        self.library = {c.name: c for c in library}
        self.effects: list[ModelEffect] = []

    def candidate(self, name: str) -> Candidate:
        """The library's candidate called ``name``."""
        return self.library[name]

    @property
    def linear(self) -> list[ModelEffect]:
        """The chosen effects that enter the regression as columns, in order."""
        return [e for e in self.effects if self.library[e.name].kind == "linear"]

    @property
    def n_profile(self) -> int:
        """Number of chosen effects searched on a grid."""
        return len(self.effects) - len(self.linear)

    def design(self, candidates: Sequence[Candidate] = ()
               ) -> tuple[np.ndarray, list[np.ndarray], dict[str, np.ndarray]]:
        """r0 (N, 6); [θ columns, chosen linear columns …]; candidate columns by name."""
        p, effects = self.problem, self.effects
        r0 = p.residual(effects)
        cols = [theta_columns(p, effects, r0)]
        for e in self.linear:
            others = [o for o in effects if o is not e]
            cols.append(effect_columns(p, self.library[e.name], others, r0, at=e))
        extra = {c.name: effect_columns(p, c, effects, r0) for c in candidates
                 if c.kind == "linear"}
        return r0, cols, extra

    def k(self) -> int:
        """Number of fitted parameters: θ, linear effects' and one per profile effect."""
        return 6 + sum(len(e.values) for e in self.effects)

    def relinearise(self, reg: Regression, iterations: int = 6) -> None:
        """Damped Gauss–Newton on θ and the linear effects' values, profile effects held.

        A step is halved until θ stays physical (c_T, J > 0) and the deviance does not
        grow: from a θ that absorbed a large effect (a CoG offset's torque turns into a
        wrong inertia) the full step overshoots.
        """
        r0, cols, _ = self.design()
        dev0 = reg.deviance(reg.fit(*reg.stack(r0, cols))[0])
        for _ in range(iterations):
            _, beta, _ = reg.fit(*reg.stack(r0, cols))
            start_problem, start_effects = self.problem, list(self.effects)
            step = 1.0
            while step > 1e-3:
                theta = start_problem.theta + step * beta[:6]
                if theta[0] > 0.0 and np.all(theta[3:] > 0.0):
                    self.problem = replace(start_problem, theta=theta)
                    self.effects = self._stepped(start_effects, step * beta)
                    r1, cols1, _ = self.design()
                    dev1 = reg.deviance(reg.fit(*reg.stack(r1, cols1))[0])
                    if dev1 <= dev0 + 1e-9:
                        break
                step *= 0.5
            else:
                self.problem, self.effects = start_problem, start_effects
                return
            converged = dev0 - dev1 < 1e-6
            r0, cols, dev0 = r1, cols1, dev1
            if converged:
                return

    def _stepped(self, effects: list[ModelEffect], beta: np.ndarray) -> list[ModelEffect]:
        """``effects`` with the linear ones moved by their part of the step ``beta``."""
        out, offset = [], 6
        for e in effects:
            if self.library[e.name].kind == "linear":
                n = len(e.values)
                out.append(e.with_values(e.values + beta[offset:offset + n]))
                offset += n
            else:
                out.append(e)
        return out

    def profile(self, reg: Regression, cand: Candidate, grid: np.ndarray,
                cols: list[np.ndarray], others: list[ModelEffect]) -> np.ndarray:
        """Deviance over ``grid`` of a profile candidate, ``cols`` re-fitted at each value."""
        name = cand.effect.parameters[0].name
        dev = np.empty(grid.size)
        for i, v in enumerate(grid):
            r = self.problem.residual([*others, cand.effect(**{name: float(v)})])
            dev[i] = reg.deviance(reg.fit(*reg.stack(r, cols))[0])
        return dev
