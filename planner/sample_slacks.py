"""Pointwise slacks of the sampled constraints (body rate, rotor slabs), numba kernels.

Used by the segment check of `mavsysid.planner.feasibility`; the rotor slabs may carry a
chance margin (`slab_spread`), the first-order spread of a slab value under the prior
covariance of θ (`mavsysid.planner.settings.PlannerSettings.rotor_confidence`).
"""

from __future__ import annotations

import numba
import numpy as np
from mavsysid.vehicle.flatness import (
    SAMPLE_NORM,
    SAMPLE_RATE,
    SAMPLE_RATE_DOT,
    SAMPLE_TORQUE,
    flat_sample,
)

__all__ = ["sample_slacks", "slab_spread"]


@numba.njit(cache=True)
def slab_spread(u: np.ndarray, thrust: float, tau: np.ndarray, sample: np.ndarray,
                 J: np.ndarray, spread: np.ndarray) -> float:
    """z σ of one slab value u·w under relative θ errors (c_T, c_M, j_x, j_y, j_z), first order.

    The allocation is diag(c_T, c_T, c_T, c_M) G, so a relative error δ of c_T (c_M)
    scales the slab's thrust and roll/pitch (yaw) terms by 1 − δ; τ = J ω̇ + ω × J ω is
    linear in J. ``spread`` is z² Σ of those five, (5, 5); c_D does not enter the wrench.
    """
    wx, wy, wz = sample[SAMPLE_RATE], sample[SAMPLE_RATE + 1], sample[SAMPLE_RATE + 2]
    ax, ay, az = (sample[SAMPLE_RATE_DOT], sample[SAMPLE_RATE_DOT + 1],
                  sample[SAMPLE_RATE_DOT + 2])
    g = np.empty(5)
    g[0] = -(u[0] * thrust + u[1] * tau[0] + u[2] * tau[1])
    g[1] = -u[3] * tau[2]
    # ∂τ/∂j_x = (ω̇x, ωx ωz, −ωx ωy), ∂τ/∂j_y = (−ωy ωz, ω̇y, ωx ωy), ∂τ/∂j_z = (ωy ωz, −ωx ωz, ω̇z).
    g[2] = J[0] * (u[1] * ax + u[2] * wx * wz - u[3] * wx * wy)
    g[3] = J[1] * (-u[1] * wy * wz + u[2] * ay + u[3] * wx * wy)
    g[4] = J[2] * (u[1] * wy * wz - u[2] * wx * wz + u[3] * az)
    var = 0.0
    for a in range(5):
        for b in range(5):
            var += g[a] * spread[a, b] * g[b]
    return np.sqrt(max(var, 0.0))


@numba.njit(cache=True)
def sample_slacks(dc: np.ndarray, s: float, lim: np.ndarray, J: np.ndarray,
                       normals: np.ndarray, bounds: np.ndarray, spread: np.ndarray,
                       v: np.ndarray, out: np.ndarray, row: int) -> None:
    """Normalised slacks at unit time s into out[row]: ‖ω‖/ω_max − 1, then per slab.

    Slab slack max(u·w + zσ − upper, lower − u·w + zσ) / scale for the wrench w and each
    slab u of `mavsysid.vehicle.allocation_polytope.AllocationSlabs` (``bounds`` = its
    lower, upper, scale; zσ from `slab_spread`, 0 when ``spread`` is all zero): with A⁺
    rows and the n² range, per rotor max(n² − n²_max, n²_min − n²) / n²_max.
    Positive means violated; NaN or inf (a singular attitude) counts as violated. The
    flatness is ``flat_to_state``'s own (`mavsysid.vehicle.flatness.flat_sample`). ``v``
    (12 + SAMPLE_SIZE,) is scratch space (no allocation per sample).
    """
    # Horner, all 12 derivatives at once: a, jerk, snap (3 each), ψ, ψ̇, ψ̈.
    v[:] = 0.0
    for j in range(dc.shape[0] - 1, -1, -1):
        for r in range(12):
            v[r] = v[r] * s + dc[j, 6 + r]
    sample = v[12:]
    if not flat_sample(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10],
                       v[11], J, sample):
        out[row] = np.inf
        return
    wx, wy, wz = sample[SAMPLE_RATE], sample[SAMPLE_RATE + 1], sample[SAMPLE_RATE + 2]
    out[row, 0] = np.sqrt(wx * wx + wy * wy + wz * wz) / lim[5] - 1.0
    # Paper Eq. (allocation): [T, J ω̇ + ω × J ω] = A n².
    thrust = lim[0] * sample[SAMPLE_NORM]
    tau = sample[SAMPLE_TORQUE:SAMPLE_TORQUE + 3]
    chance = spread[0, 0] + spread[1, 1] + spread[2, 2] + spread[3, 3] + spread[4, 4] > 0.0
    for i in range(normals.shape[0]):
        n2 = (normals[i, 0] * thrust + normals[i, 1] * tau[0] + normals[i, 2] * tau[1]
              + normals[i, 3] * tau[2])
        margin = slab_spread(normals[i], thrust, tau, sample, J, spread) if chance else 0.0
        out[row, 1 + i] = max(n2 + margin - bounds[1, i],
                              bounds[0, i] - n2 + margin) / bounds[2, i]
    for f in range(out.shape[1]):
        if not out[row, f] <= 1e300:
            out[row, f] = np.inf
