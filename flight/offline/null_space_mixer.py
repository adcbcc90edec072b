"""Mixers: a wrench [T, τ_x, τ_y, τ_z] to rotor speeds within the rotor box.

Two mixers, chosen by the vehicle file's ``[limits] allocation``
(`mavsysid.vehicle.config_types.ALLOCATION_MODES`):

- ``"pseudo_inverse"`` (`pseudo_inverse_mix`): n² = A⁺ w, the mixer of ArduPilot, PX4 and
  RotorS's Lee controller. At the rotor limits yaw torque is given up first (the largest
  share of the A⁺ yaw column that keeps every rotor in the box), then commands are clipped.
- ``"exact"`` (`null_space_mix`): n² = A⁺ w + N z, N an orthonormal basis of the null space
  of A (k − 4 columns). z is the least-norm shift that brings n² into the box, so the
  mixer equals A⁺ wherever A⁺ fits, and stays continuous in w beyond. That is a tiny
  strictly convex QP, min |z|² subject to n²_min ≤ A⁺w + N z ≤ n²_max, solved exactly by
  the dual active-set method of Goldfarb and Idnani (1983), which starts at z = 0 and
  only adds the constraints A⁺ w violates. Whether w is reachable at all, and how much yaw
  to give up when it is not, comes from the exact allocation polytope's slabs
  (`mavsysid.vehicle.allocation_polytope.zonotope_slabs`): w with its yaw torque scaled
  by the largest s ∈ [0, 1] that the slabs allow. If no s ∈ [0, 1] is reachable, the
  wrench is mixed as by the A⁺ mixer (yaw given up, then clipped).

Both kernels are numba functions of plain arrays, for the controller's per-tick loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.vehicle.allocation_polytope import zonotope_slabs

__all__ = ["NullSpaceMixer", "least_norm_box_shift", "null_space_mix", "null_space_mixer",
           "pseudo_inverse_mix"]

# Box violations up to this fraction of the n² range count as inside (then clipped away);
# slab violations likewise, as a fraction of the slab's width.
_BOX_TOL = 1e-9
# A step direction shorter than this fraction of the constraint normal is zero: the new
# constraint's normal lies in the span of the active ones.
_DEPENDENT = 1e-9


@dataclass(frozen=True)
class NullSpaceMixer:
    """Arrays of the exact (null-space) mixer of one allocation matrix.

    Attributes
    ----------
    pinv : ndarray, shape (k, 4)
        A⁺, per [N, N·m, N·m, N·m] → (rad/s)².
    null : ndarray, shape (k, k − 4)
        Orthonormal basis of the null space of A.
    normals : ndarray, shape (m, 4)
        Slab normals of the reachable wrenches.
    lower, upper : ndarray, shape (m,)
        Slab bounds.
    tolerance : ndarray, shape (m,)
        Slab violation counted as inside (a fraction ``_BOX_TOL`` of each slab's width).
    n2_min, n2_max : float
        Rotor box, (rad/s)².
    """

    pinv: np.ndarray
    null: np.ndarray
    normals: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    tolerance: np.ndarray
    n2_min: float
    n2_max: float


def null_space_mixer(A: np.ndarray, pinv: np.ndarray, n2_min: float,
                     n2_max: float) -> NullSpaceMixer:
    """Precompute the exact mixer of allocation matrix ``A`` (4, k) with ``pinv`` = A⁺ (k, 4).

    ``pinv`` is passed in so that the mixer uses the A⁺ of record bit for bit
    (`mavsysid.vehicle.allocation.allocation_pinv`).

    Parameters
    ----------
    A : ndarray, shape (4, k)
        Allocation matrix.
    pinv : ndarray, shape (k, 4)
        Its A⁺.
    n2_min, n2_max : float
        The n² box, (rad/s)².
    """
    A = np.asarray(A, dtype=float)
    _, _, vt = np.linalg.svd(A)
    slabs = zonotope_slabs(A, n2_min, n2_max)
    c = np.ascontiguousarray
    return NullSpaceMixer(
        pinv=c(pinv, dtype=float), null=c(vt[4:].T), normals=c(slabs.normals),
        lower=c(slabs.lower), upper=c(slabs.upper), tolerance=c(_BOX_TOL * slabs.scale),
        n2_min=float(n2_min), n2_max=float(n2_max),
    )


@numba.njit(cache=True)
def pseudo_inverse_mix(w, pinv, n2_min, n2_max, out):
    """A⁺ mixing of wrench ``w`` (4,): rotor speeds into ``out`` (k,); True if saturated.

    Thrust, roll and pitch first; yaw torque is given up before anything else, as
    autopilots do, since the yaw authority of rotor moments is small.

    Parameters
    ----------
    w : ndarray, shape (4,)
        Wrench [T, τ_x, τ_y, τ_z], N and N·m.
    pinv : ndarray, shape (k, 4)
        A⁺.
    n2_min, n2_max : float
        The n² box, (rad/s)².
    out : ndarray, shape (k,)
        Receives the rotor speeds, rad/s.
    """
    k = pinv.shape[0]
    base = np.empty(k)
    yaw_part = np.empty(k)
    for i in range(k):
        base[i] = pinv[i, 0] * w[0] + pinv[i, 1] * w[1] + pinv[i, 2] * w[2]
        yaw_part[i] = pinv[i, 3] * w[3]
    scale = 1.0
    for i in range(k):
        if yaw_part[i] > 0.0 and base[i] + yaw_part[i] > n2_max:
            scale = min(scale, (n2_max - base[i]) / yaw_part[i])
        elif yaw_part[i] < 0.0 and base[i] + yaw_part[i] < n2_min:
            scale = min(scale, (n2_min - base[i]) / yaw_part[i])
    scale = max(scale, 0.0)
    clipped = scale < 1.0
    for i in range(k):
        v = base[i] + scale * yaw_part[i]
        if v < n2_min:
            v = n2_min
            clipped = True
        elif v > n2_max:
            v = n2_max
            clipped = True
        out[i] = np.sqrt(v)
    return clipped


@numba.njit(cache=True)
def _box_slack(b, null, z, j, n2_min, n2_max):
    """Slack of box constraint j of n² = b + N z: j < k lower bound of rotor j, else upper."""
    k = b.shape[0]
    i = j if j < k else j - k
    n2 = b[i]
    for a in range(null.shape[1]):
        n2 += null[i, a] * z[a]
    return n2 - n2_min if j < k else n2_max - n2


@numba.njit(cache=True)
def _constraint_normal(null, j, out):
    """Gradient of `_box_slack` j with respect to z, into ``out`` (d,)."""
    k = null.shape[0]
    sign = 1.0 if j < k else -1.0
    i = j if j < k else j - k
    for a in range(null.shape[1]):
        out[a] = sign * null[i, a]


@numba.njit(cache=True)
def _factorise(null, active, q, Q, R):
    """Q[:, :q] R[:q, :q] = the active constraints' normals (modified Gram–Schmidt)."""
    d = null.shape[1]
    col = np.empty(d)
    for c in range(q):
        _constraint_normal(null, active[c], col)
        for a in range(c):
            dot = 0.0
            for e in range(d):
                dot += Q[e, a] * col[e]
            R[a, c] = dot
            for e in range(d):
                col[e] -= dot * Q[e, a]
        nrm = np.sqrt(np.sum(col * col))
        R[c, c] = nrm
        for e in range(d):
            Q[e, c] = col[e] / nrm


@numba.njit(cache=True)
def _step_directions(npl, Q, R, q, zdir, r):
    """Primal step ``zdir`` = n⁺ projected off the active normals; dual ``r`` = R⁻¹ Q₁ᵀ n⁺."""
    d = npl.shape[0]
    for e in range(d):
        zdir[e] = npl[e]
    for a in range(q):
        dot = 0.0
        for e in range(d):
            dot += Q[e, a] * npl[e]
        r[a] = dot
        for e in range(d):
            zdir[e] -= dot * Q[e, a]
    for a in range(q - 1, -1, -1):  # back substitution
        for c in range(a + 1, q):
            r[a] -= R[a, c] * r[c]
        r[a] /= R[a, a]


@numba.njit(cache=True)
def least_norm_box_shift(b, null, n2_min, n2_max, tol, z):
    """Least-norm z (d,) with n2_min ≤ b + N z ≤ n2_max (± ``tol``); False if none exists.

    Goldfarb–Idnani dual active set with identity Hessian: from z = 0, repeatedly take the
    most violated box constraint and step (primal, dual, or both) until it is active,
    dropping active constraints whose multipliers would turn negative.

    Parameters
    ----------
    b : ndarray, shape (k,)
        The A⁺ rotor n², (rad/s)².
    null : ndarray, shape (k, d)
        Null-space basis N of A.
    n2_min, n2_max : float
        The n² box, (rad/s)².
    tol : float
        Allowed violation, (rad/s)².
    z : ndarray, shape (d,)
        Receives the shift.
    """
    k, d = null.shape
    active = np.empty(d + 1, dtype=np.int64)
    u = np.zeros(d + 1)
    Q = np.zeros((d, d))
    R = np.zeros((d, d))
    npl, zdir, r = np.empty(d), np.empty(d), np.empty(d + 1)
    z[:] = 0.0
    q = 0
    for _ in range(8 * k + 8):
        p, worst = -1, -tol
        for j in range(2 * k):
            s = _box_slack(b, null, z, j, n2_min, n2_max)
            if s < worst:
                p, worst = j, s
        if p < 0:
            return True
        _constraint_normal(null, p, npl)
        u_plus = 0.0
        for _ in range(2 * d + 2):
            _step_directions(npl, Q, R, q, zdir, r)
            t1, drop = np.inf, -1
            for a in range(q):
                if r[a] > 0.0 and u[a] / r[a] < t1:
                    t1, drop = u[a] / r[a], a
            zz = np.sum(zdir * npl)
            t2 = np.inf
            if q < d and zz > _DEPENDENT**2 * np.sum(npl * npl):
                t2 = -_box_slack(b, null, z, p, n2_min, n2_max) / zz
            if t1 == np.inf and t2 == np.inf:
                return False  # the box constraints contradict each other
            t = min(t1, t2)
            if t2 < np.inf:
                z += t * zdir
            for a in range(q):
                u[a] -= t * r[a]
            u_plus += t
            if t2 <= t1:  # constraint p is active now
                active[q], u[q] = p, u_plus
                q += 1
                _factorise(null, active, q, Q, R)
                break
            for a in range(drop, q - 1):  # drop the blocking constraint, keep going
                active[a], u[a] = active[a + 1], u[a + 1]
            q -= 1
            _factorise(null, active, q, Q, R)
    return False


@numba.njit(cache=True)
def _yaw_scale(w, normals, lower, upper, tol):
    """Largest s ∈ [0, 1] with [T, τ_x, τ_y, s τ_z] inside the slabs; −1 if there is none.

    The wrenches along s form an interval of the polytope; it need not contain s = 0
    (zero yaw torque), as differential thrust and rotor moments are coupled.
    """
    s_lo, s_hi = 0.0, 1.0
    for j in range(normals.shape[0]):
        v0 = normals[j, 0] * w[0] + normals[j, 1] * w[1] + normals[j, 2] * w[2]
        de = normals[j, 3] * w[3]
        lo, hi = lower[j] - tol[j] - v0, upper[j] + tol[j] - v0
        if de > 0.0:
            s_lo, s_hi = max(s_lo, lo / de), min(s_hi, hi / de)
        elif de < 0.0:
            s_lo, s_hi = max(s_lo, hi / de), min(s_hi, lo / de)
        elif lo > 0.0 or hi < 0.0:
            return -1.0
    return s_hi if s_lo <= s_hi else -1.0


@numba.njit(cache=True)
def null_space_mix(w, pinv, null, normals, lower, upper, tol, n2_min, n2_max, out):
    """Exact mixing of wrench ``w`` (4,): rotor speeds into ``out`` (k,); True if saturated.

    Arguments are the fields of a `NullSpaceMixer`. Saturated means yaw torque was given
    up or a rotor command clipped; a reachable wrench is produced exactly.

    Parameters
    ----------
    w : ndarray, shape (4,)
        Wrench [T, τ_x, τ_y, τ_z], N and N·m.
    pinv : ndarray, shape (k, 4)
        A⁺.
    null : ndarray, shape (k, d)
        Null-space basis of A.
    normals : ndarray, shape (F, 4)
        Slab normals of the allocation polytope.
    lower, upper : ndarray, shape (F,)
        Slab bounds.
    tol : ndarray, shape (F,)
        Slab violation counted as inside.
    n2_min, n2_max : float
        The n² box, (rad/s)².
    out : ndarray, shape (k,)
        Receives the rotor speeds, rad/s.
    """
    s = _yaw_scale(w, normals, lower, upper, tol)
    if s < 0.0:
        return pseudo_inverse_mix(w, pinv, n2_min, n2_max, out)
    k, d = null.shape
    wy = w[3] * s
    b = np.empty(k)
    for i in range(k):
        b[i] = pinv[i, 0] * w[0] + pinv[i, 1] * w[1] + pinv[i, 2] * w[2] + pinv[i, 3] * wy
    z = np.empty(d)
    solved = least_norm_box_shift(b, null, n2_min, n2_max, _BOX_TOL * (n2_max - n2_min), z)
    for i in range(k):
        v = b[i]
        for a in range(d):
            v += null[i, a] * z[a]
        out[i] = np.sqrt(min(max(v, n2_min), n2_max))
    return s < 1.0 or not solved
