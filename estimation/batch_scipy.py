"""The batch refinement's problem solved by `scipy.optimize.least_squares` instead.

Kept as the reference the refinement (`mavsysid.estimation.batch.refine`) is measured
against: same residuals, same sparse Jacobian, scipy's trust-region reflective method with
LSMR for the sparse steps (its only choice for a sparse Jacobian; ``method="lm"`` needs a
dense one). The unknowns are the nodes' errors from the start (x_k = x_k⁰ ⊞ d_k) and the
scaled θ error. The Jacobian is the one at the current nodes; it differs from the
Jacobian in d by an invertible factor (the chart's), so the stationary points agree.
`bench/estimate_speed.py` times both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from mavsysid.estimation.batch_problem import ShootingProblem, apply_step
from scipy.optimize import least_squares

__all__ = ["LeastSquaresResult", "solve_least_squares"]


@dataclass(frozen=True)
class LeastSquaresResult:
    """What `solve_least_squares` found.

    Attributes
    ----------
    theta : ndarray, shape (6,)
        θ at the end, SI.
    nodes : ndarray, shape (K, 13)
    cost : float
        ½ Σ r² at the end.
    evaluations : int
        Residual evaluations.
    status : int
        ``least_squares``' status (> 0: converged by a tolerance).
    """

    theta: np.ndarray
    nodes: np.ndarray
    cost: float
    evaluations: int
    status: int


def solve_least_squares(problem: ShootingProblem, nodes: np.ndarray, theta: np.ndarray,
                        max_evaluations: int = 30, tol: float = 1e-10) -> LeastSquaresResult:
    """Minimise the shooting problem's ½|r|² with `scipy.optimize.least_squares`.

    Parameters
    ----------
    problem : ShootingProblem
        With its defect whitening set (`mavsysid.estimation.batch.shooting_problem`).
    nodes : ndarray, shape (K, 13)
        The start.
    theta : ndarray, shape (6,)
        The start, SI.
    max_evaluations : int
        ``max_nfev``.
    tol : float
        ``ftol``, ``xtol`` and ``gtol``.
    """
    K = nodes.shape[0]
    model = problem.model

    def unpack(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return apply_step(model, nodes, theta, u[:12 * K].reshape(K, 12), u[12 * K:])

    def fun(u: np.ndarray) -> np.ndarray:
        return problem.residuals(*unpack(u))

    def jac(u: np.ndarray) -> sp.csr_matrix:
        return problem.jacobian(*unpack(u))[1]

    sol = least_squares(fun, np.zeros(12 * K + 6), jac=jac, method="trf", tr_solver="lsmr",
                        x_scale="jac", max_nfev=max_evaluations, ftol=tol, xtol=tol, gtol=tol)
    end_nodes, end_theta = unpack(sol.x)
    return LeastSquaresResult(end_theta, end_nodes, float(sol.cost), int(sol.nfev),
                              int(sol.status))
