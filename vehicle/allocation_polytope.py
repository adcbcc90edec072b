"""Which wrenches the rotors can produce: the allocation polytope as slabs, and an LP reference.

Paper Eq. (allocation): w = [T, τ_x, τ_y, τ_z] = A n² with each n_i² in a box [n²_lo, n²_hi].
The wrenches the rotors reach are the image of that box under A, a zonotope: the Minkowski
sum of the segments A_i [n²_lo, n²_hi]. A zonotope is centrally symmetric, so each of its
facet-normal directions u bounds it by a *slab*

    u·c − r(u) ≤ u·w ≤ u·c + r(u),  c = A (n²_lo + n²_hi)/2,  r(u) = Σ_i |u·A_i| (n²_hi − n²_lo)/2,

and in 4-D every facet normal is orthogonal to three of the columns A_i. Enumerating the
C(k, 3) triples (20 for a hexacopter, 56 for an octocopter) gives all facet normals;
a triple that spans no facet only adds a valid, redundant slab (r(u) is the support
function, so every slab holds on the whole zonotope). This is `zonotope_slabs`: exact,
and null-space use is implied (any n² in the box counts).

`pseudo_inverse_slabs` is the same form for the mixer ArduPilot, PX4 and RotorS's Lee
controller implement: n² = A⁺ w must itself lie in the box (for 4 rotors A⁺ = A⁻¹ and
both sets are equal; for more rotors it is a subset). Its slab i is n²_lo ≤ (A⁺w)_i ≤
n²_hi, scaled by n²_hi, exactly the planner's earlier rotor slack.

`wrench_reachable_lp` is the independent reference: a feasibility LP (HiGHS) over the
rotor box with A n² = w.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv
from mavsysid.vehicle.config_types import ALLOCATION_MODES, VehicleConfig

__all__ = ["ALLOCATION_MODES", "AllocationSlabs", "allocation_slabs", "pseudo_inverse_slabs",
           "wrench_reachable_lp", "zonotope_slabs"]

# Unit normals closer than this (in the row-scaled wrench space) are one direction.
_SAME_DIRECTION = 1e-9
# A triple of columns whose 3×3 minors are all below this (relative) spans no hyperplane.
_RANK_TOL = 1e-10


@dataclass(frozen=True)
class AllocationSlabs:
    """Reachable wrenches as slabs ``lower ≤ normals @ w ≤ upper``.

    Attributes
    ----------
    normals : ndarray, shape (m, 4)
        Slab directions in wrench space, per [N, N·m, N·m, N·m].
    lower, upper : ndarray, shape (m,)
        Slab bounds, in the units of ``normals @ w``.
    scale : ndarray, shape (m,)
        Divisor that makes a slack dimensionless: ``max(normals @ w − upper,
        lower − normals @ w) / scale`` is ≤ 0 inside and about the fraction of the
        rotor range by which a wrench is outside.
    """

    normals: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray

    def slack(self, wrench: np.ndarray) -> np.ndarray:
        """Largest scaled slab violation, shape (...,) for wrenches (..., 4); ≤ 0 reachable.

        Parameters
        ----------
        wrench : ndarray, shape (..., 4)
            [T, τ_x, τ_y, τ_z], N and N·m.
        """
        v = np.asarray(wrench, dtype=float) @ self.normals.T
        return (np.maximum(v - self.upper, self.lower - v) / self.scale).max(axis=-1)

    def contains(self, wrench: np.ndarray) -> np.ndarray:
        """Whether each wrench (..., 4) is reachable, bool (...,).

        Parameters
        ----------
        wrench : ndarray, shape (..., 4)
            [T, τ_x, τ_y, τ_z], N and N·m.
        """
        return self.slack(wrench) <= 0.0


def _row_scale(A: np.ndarray) -> np.ndarray:
    """Per-row magnitudes of A: thrust and yaw rows differ by ~10², scale them to O(1)."""
    return np.abs(A).max(axis=1)


def zonotope_slabs(A: np.ndarray, n2_lower: float, n2_upper: float) -> AllocationSlabs:
    """The exact allocation polytope {A n² : n² ∈ [n2_lower, n2_upper]^k} as slabs.

    Parameters
    ----------
    A : ndarray, shape (4, k)
        Allocation matrix (`mavsysid.vehicle.allocation.allocation_matrix`), k ≥ 4, rank 4.
    n2_lower, n2_upper : float
        Rotor speed squared range, (rad/s)².

    Returns
    -------
    AllocationSlabs
        One slab per facet-normal direction; ``scale`` is the slab's width.
    """
    A = np.asarray(A, dtype=float)
    d = _row_scale(A)
    # Columns in the row-scaled space, each its full n² range long.
    G = A / d[:, None] * (n2_upper - n2_lower)
    found: list[np.ndarray] = []
    for triple in combinations(range(G.shape[1]), 3):
        M = G[:, triple].T  # (3, 4): the normal is orthogonal to its rows
        # Generalised cross product: the cofactors along the missing column.
        u = np.array([(-1) ** j * np.linalg.det(np.delete(M, j, axis=1)) for j in range(4)])
        norm = np.linalg.norm(u)
        if norm <= _RANK_TOL * np.prod(np.linalg.norm(M, axis=1)):
            continue
        u /= norm
        u *= np.sign(u[np.flatnonzero(np.abs(u) > 1e-12)[0]])  # canonical sign
        if not any(np.abs(u - f).max() < _SAME_DIRECTION for f in found):
            found.append(u)
    U = np.array(found)
    half = 0.5 * np.abs(U @ G).sum(axis=1)
    centre = U @ (A / d[:, None]).sum(axis=1) * 0.5 * (n2_lower + n2_upper)
    # u·(D⁻¹ w) = (D⁻¹ u)·w: fold the row scaling into the normals.
    return AllocationSlabs(np.ascontiguousarray(U / d[None, :]), centre - half, centre + half,
                           2.0 * half)


def pseudo_inverse_slabs(A: np.ndarray, n2_lower: float, n2_upper: float) -> AllocationSlabs:
    """The wrenches whose minimum-norm allocation A⁺ w lies in the rotor box, as slabs.

    Parameters
    ----------
    A : ndarray, shape (4, k)
        Allocation matrix.
    n2_lower, n2_upper : float
        Rotor speed squared range, (rad/s)².

    Returns
    -------
    AllocationSlabs
        Slab i is rotor i: ``normals`` = A⁺ rows, ``scale`` = n2_upper.
    """
    k = np.asarray(A).shape[1]
    return AllocationSlabs(np.ascontiguousarray(np.linalg.pinv(A)), np.full(k, n2_lower),
                           np.full(k, n2_upper), np.full(k, n2_upper))


def allocation_slabs(config: VehicleConfig, n2_lower: float, n2_upper: float,
                     theta: np.ndarray | None = None, mode: str | None = None
                     ) -> AllocationSlabs:
    """The slabs of a vehicle's reachable wrenches.

    Parameters
    ----------
    config : VehicleConfig
        Rotor geometry; its ``allocation`` is the mode by default.
    n2_lower, n2_upper : float
        Rotor speed squared range, (rad/s)² (e.g. less a headroom).
    theta : ndarray, shape (6,), optional
        Parameters [c_T, c_D, c_M, …] for the allocation; the config's nominal θ by default.
    mode : {"exact", "pseudo_inverse"}, optional
        Overrides ``config.allocation``.

    Returns
    -------
    AllocationSlabs
    """
    mode = config.allocation if mode is None else mode
    if mode == "pseudo_inverse":
        # The planner's A⁺ of record (cached), so slacks match it to the last bit.
        pinv = allocation_pinv(config, theta)
        k = pinv.shape[0]
        return AllocationSlabs(np.ascontiguousarray(pinv), np.full(k, n2_lower),
                               np.full(k, n2_upper), np.full(k, n2_upper))
    if mode == "exact":
        return zonotope_slabs(allocation_matrix(config, theta), n2_lower, n2_upper)
    raise ValueError(f"allocation mode {mode!r}: expected one of {', '.join(ALLOCATION_MODES)}")


def wrench_reachable_lp(A: np.ndarray, n2_lower: float, n2_upper: float,
                        wrench: np.ndarray) -> bool:
    """Whether some n² ∈ [n2_lower, n2_upper]^k gives A n² = wrench: a HiGHS feasibility LP.

    Solved in scaled variables s = (n² − n2_lower)/(n2_upper − n2_lower) ∈ [0, 1]^k with the
    rows of A scaled to O(1), so that HiGHS's tolerances (1e-7) are relative to the rotor
    range. Stacking wrenches (S, 4) checks all of them in one block-diagonal LP (True
    only if every one is reachable).

    Parameters
    ----------
    A : ndarray, shape (4, k)
        Allocation matrix.
    n2_lower, n2_upper : float
        Rotor speed squared range, (rad/s)².
    wrench : ndarray, shape (4,) or (S, 4)
        [T, τ_x, τ_y, τ_z], N and N·m.

    Returns
    -------
    bool
    """
    from scipy.optimize import linprog
    from scipy.sparse import block_diag

    A = np.asarray(A, dtype=float)
    w = np.atleast_2d(np.asarray(wrench, dtype=float))
    d = _row_scale(A)
    M = A / d[:, None] * (n2_upper - n2_lower)
    rhs = (w - A.sum(axis=1) * n2_lower) / d
    A_eq = block_diag([M] * w.shape[0], format="csr") if w.shape[0] > 1 else M
    result = linprog(np.zeros(A.shape[1] * w.shape[0]), A_eq=A_eq, b_eq=rhs.ravel(),
                     bounds=(0.0, 1.0), method="highs")
    if result.status not in (0, 2):
        raise RuntimeError(f"allocation LP: {result.message}")
    return result.status == 0
