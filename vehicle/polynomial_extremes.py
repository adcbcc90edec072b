"""Exact extremes of a polynomial trajectory segment's kinematic quantities.

A segment is a polynomial in its local time τ ∈ [0, T] per position axis and in yaw, so
every quantity checked on it has its extremes at the segment ends or where a polynomial
vanishes: the derivative of the quantity itself (a coordinate, a signed vertical speed), of
its square (a norm, an absolute value; squared norms are polynomials too), or, for the lean
angle of the thrust direction, the polynomial u′w − ½uw′ with u = a_z + g and
w = a_x² + a_y² (the numerator of d cos θ/dτ). The real roots in [0, T] are the
eigenvalues of companion matrices (batched per degree), polished by Newton steps; a grid of
samples is added in case a root is lost to rounding. Every quantity is evaluated at the
union of all these candidates, so each one's largest and smallest value is among them:
nothing escapes between samples, which is what the streamer's safety check and the
planner's autopilot envelope both need (`segment_extremes`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from mavsysid.vehicle.constants import GRAVITY

__all__ = ["EXTREME_GRID", "QUANTITIES", "real_roots", "segment_extremes", "tilt_angle"]

#: Samples per segment besides the exact extremes (a safety net against lost roots).
EXTREME_GRID = 33
#: Newton steps that polish each root of a companion matrix.
_NEWTON_STEPS = 2

#: The quantities `segment_extremes` knows (world ENU, z up; SI units):
#: ``x``, ``y``, ``z`` position m; ``speed`` ‖v‖, ``speed_xy`` ‖v_xy‖, ``vertical_speed``
#: v_z m/s; ``thrust`` ‖a + g ẑ‖, ``accel_xy`` ‖a_xy‖, ``vertical_accel`` a_z m/s²;
#: ``jerk`` ‖j‖, ``jerk_xy`` ‖j_xy‖, ``jerk_z`` |j_z| m/s³; ``tilt`` the lean angle of
#: a + g ẑ from the vertical, rad; ``yaw`` ψ rad, ``yaw_rate`` |ψ̇| rad/s,
#: ``yaw_acceleration`` |ψ̈| rad/s².
QUANTITIES = ("x", "y", "z", "speed", "speed_xy", "vertical_speed", "thrust", "accel_xy",
              "vertical_accel", "jerk", "jerk_xy", "jerk_z", "tilt", "yaw", "yaw_rate",
              "yaw_acceleration")


def tilt_angle(acceleration: np.ndarray) -> np.ndarray:
    """Lean angle of the thrust direction a + g ẑ from the vertical, rad.

    Parameters
    ----------
    acceleration : ndarray, shape (S, 3)
        Acceleration, m/s², world ENU (z up).

    Returns
    -------
    ndarray, shape (S,)
        In [0, π]; above π/2 the thrust would have to point down.
    """
    a = np.asarray(acceleration, dtype=float)
    return np.arctan2(np.linalg.norm(a[:, :2], axis=1), a[:, 2] + GRAVITY)


def _der(c: np.ndarray) -> np.ndarray:
    """d/dτ of a polynomial (increasing powers)."""
    return c[1:] * np.arange(1, c.size) if c.size > 1 else np.zeros(1)


def _add(*polys: np.ndarray) -> np.ndarray:
    """The sum of polynomials of any lengths."""
    out = np.zeros(max(c.size for c in polys))
    for c in polys:
        out[:c.size] += c
    return out


def _horner(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Rows of polynomials ``c`` (K, n) at their points ``x`` (K, m)."""
    out = np.zeros_like(x)
    for j in range(c.shape[1] - 1, -1, -1):
        out = out * x + c[:, j:j + 1]
    return out


def real_roots(polys: Sequence[np.ndarray], duration: float) -> np.ndarray:
    """The real roots in [0, ``duration``] of every polynomial of ``polys``.

    Parameters
    ----------
    polys : sequence of ndarray
        Polynomials, coefficients of increasing powers of τ. Constant, all-zero and
        non-finite ones have no roots here.
    duration : float
        T, s.

    Returns
    -------
    ndarray, shape (R,)
        Unsorted, each polished by Newton steps; repeats possible.
    """
    kept = []
    for c in polys:
        nonzero = np.flatnonzero(c)
        if nonzero.size and nonzero[-1] > 0 and np.all(np.isfinite(c)):
            kept.append(c[:nonzero[-1] + 1])
    if not kept:
        return np.empty(0)
    # One batched eigenvalue call: each companion matrix is padded to the largest size with
    # a diagonal of r₀ outside [0, T] (block diagonal: the roots stay exactly the roots).
    m = max(c.size for c in kept) - 1
    outside = -1.0 - duration
    c = np.zeros((len(kept), m + 1))
    companion = np.zeros((len(kept), m, m))
    for i, row in enumerate(kept):
        k = row.size - 1
        c[i, :row.size] = row
        companion[i, np.arange(1, k), np.arange(k - 1)] = 1.0
        companion[i, :k, k - 1] = -row[:-1] / row[-1]
        companion[i, np.arange(k, m), np.arange(k, m)] = outside
    # The rotated companion matrix has smaller errors (as numpy's polyroots uses it).
    z = np.linalg.eigvals(companion[:, ::-1, ::-1])
    x = z.real
    slope = c[:, 1:] * np.arange(1, m + 1)
    for _ in range(_NEWTON_STEPS):
        d = _horner(slope, x)
        step = np.divide(_horner(c, x), d, out=np.zeros_like(x), where=d != 0.0)
        x = np.where(np.isfinite(step), x - step, x)
    x = x[np.abs(z.imag) <= 1e-9 * max(1.0, duration)]
    return x[(x >= 0.0) & (x <= duration)]


def _stationary(name: str, d: list[np.ndarray], yaw: list[np.ndarray]) -> list[np.ndarray]:
    """Polynomials whose roots hold the interior extremes of quantity ``name``.

    ``d[k]`` is the k-th τ-derivative of position (3, ·), ``yaw[k]`` of yaw.
    """
    a = d[2]
    axis = {"x": d[0][0], "y": d[0][1], "z": d[0][2], "vertical_speed": d[1][2],
            "vertical_accel": a[2], "yaw": yaw[0]}
    if name in axis:
        return [_der(axis[name])]
    gravity = _add(a[2], np.array([GRAVITY]))
    rows = {"speed": d[1], "speed_xy": d[1][:2], "thrust": [a[0], a[1], gravity],
            "accel_xy": a[:2], "jerk": d[3], "jerk_xy": d[3][:2], "jerk_z": d[3][2:],
            "yaw_rate": yaw[1:2], "yaw_acceleration": yaw[2:3]}
    if name in rows:  # d/dτ Σ c² = 2 Σ c c′: the zeros of an absolute value are in too
        return [_add(*(np.convolve(c, _der(c)) for c in rows[name]))]
    if name == "tilt":
        w = _add(np.convolve(a[0], a[0]), np.convolve(a[1], a[1]))
        return [_add(np.convolve(_der(gravity), w), -0.5 * np.convolve(gravity, _der(w)))]
    raise KeyError(f"unknown quantity {name!r}; known: {', '.join(QUANTITIES)}")


def _values(name: str, p: list[np.ndarray], yaw: list[np.ndarray]) -> np.ndarray:
    """Quantity ``name`` from position derivatives ``p[k]`` (C, 3) and yaw ones (C,)."""
    v, a, j = p[1], p[2], p[3]
    simple = {"x": p[0][:, 0], "y": p[0][:, 1], "z": p[0][:, 2], "vertical_speed": v[:, 2],
              "vertical_accel": a[:, 2], "jerk_z": np.abs(j[:, 2]), "yaw": yaw[0],
              "yaw_rate": np.abs(yaw[1]), "yaw_acceleration": np.abs(yaw[2])}
    if name in simple:
        return simple[name]
    if name == "tilt":
        return tilt_angle(a)
    if name == "thrust":
        return np.sqrt(a[:, 0] ** 2 + a[:, 1] ** 2 + (a[:, 2] + GRAVITY) ** 2)
    rows = {"speed": v, "speed_xy": v[:, :2], "accel_xy": a[:, :2], "jerk": j,
            "jerk_xy": j[:, :2]}[name]
    return np.sqrt(np.sum(rows**2, axis=1))


def segment_extremes(position_coeffs: np.ndarray, yaw_coeffs: np.ndarray, duration: float,
                     names: Sequence[str] = QUANTITIES, exact: bool = True
                     ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every candidate extreme of each quantity ``names`` (see `QUANTITIES`) on a segment.

    Parameters
    ----------
    position_coeffs : ndarray, shape (3, N)
        Per axis (ENU, z up), coefficients of increasing powers of τ, m/s^k.
    yaw_coeffs : ndarray, shape (Ny,)
        Yaw coefficients of increasing powers of τ, rad/s^k.
    duration : float
        T, s.
    names : sequence of str
        The quantities wanted.
    exact : bool
        False: the grid only (no roots), a quick lower bound of each largest value.

    Returns
    -------
    dict
        Name → (τ, values), both shape (C,): the quantity's largest and smallest value on
        [0, T] are among ``values`` (non-finite coefficients give non-finite values).
    """
    pc = np.atleast_2d(np.asarray(position_coeffs, dtype=float))
    yc = np.atleast_1d(np.asarray(yaw_coeffs, dtype=float))
    n, ny = pc.shape[1], yc.size
    d = [pc[:, k:] * _falling(n, k) if k < n else np.zeros((3, 1)) for k in range(4)]
    yaw = [yc[k:] * _falling(ny, k) if k < ny else np.zeros(1) for k in range(3)]
    with np.errstate(all="ignore"):
        tau = np.linspace(0.0, duration, EXTREME_GRID)
        if exact:
            polys = [c for name in names for c in _stationary(name, d, yaw)]
            tau = np.concatenate([tau, real_roots(polys, float(duration))])
        powers = tau[:, None] ** np.arange(max(n, ny))
        p = [powers[:, :c.shape[1]] @ c.T for c in d]
        y = [powers[:, :c.size] @ c for c in yaw]
        return {name: (tau, _values(name, p, y)) for name in names}


def _falling(n: int, k: int) -> np.ndarray:
    """j!/(j−k)! for j = k … n−1: the factors of the k-th derivative's coefficients."""
    j = np.arange(k, n, dtype=float)
    out = np.ones_like(j)
    for i in range(k):
        out *= j - i
    return out
