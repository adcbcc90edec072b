"""4-D polynomial segments: minimum-snap position and minimum-yaw-rate yaw.

Paper Section "Motion Planning", Eq. (min_snap_optimization): a segment is a 10-coefficient
(degree 9) polynomial per position axis and a 6-coefficient (degree 5) polynomial in yaw,
so that a chain of segments is continuous up to snap and yaw acceleration (and hence in
rotor speeds). The *first* connection to a sampled state fixes the start derivatives and
the end position and yaw, and leaves the end derivatives free; it minimises
∫‖d⁴p/dt⁴‖² dt per axis and, for yaw, ∫ψ̇² dt (the paper's "minimum-angular-velocity"
yaw segments, read as the yaw *rate*, derivative order 1). Every other connection is
fully constrained (Hermite interpolation).

The closed form's matrices, the same for every segment, are in
`mavsysid.planner.unit_interval`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from mavsysid.planner.unit_interval import (
    DERIVATIVE_MAP,
    POSITION_COEFFS,
    POSITION_COST,
    POSITION_DERIVS,
    POSITION_FREE_END,
    POSITION_HERMITE,
    POWERS,
    YAW_COEFFS,
    YAW_COST,
    YAW_DERIVS,
    YAW_FREE_END,
    YAW_HERMITE,
)
from mavsysid.vehicle.trajectory import FlatOutputs, PiecewisePolynomial

__all__ = [
    "Segment", "VertexState", "connect_fixed", "connect_free_end", "duration_range",
    "snap_cost", "stop_segment", "to_piecewise", "yaw_rate_cost",
]


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class VertexState:
    """A flat state at a graph vertex: paper Eq. (flat_state).

    Attributes
    ----------
    position : ndarray, shape (5, 3)
        Position (m), velocity (m/s), acceleration (m/s²), jerk (m/s³) and snap (m/s⁴),
        world ENU.
    yaw : ndarray, shape (3,)
        Yaw (rad), yaw rate (rad/s) and yaw acceleration (rad/s²).
    """

    position: np.ndarray
    yaw: np.ndarray

    def __post_init__(self) -> None:
        p = np.array(self.position, dtype=float)
        y = np.array(self.yaw, dtype=float)
        if p.shape != (POSITION_DERIVS, 3) or y.shape != (YAW_DERIVS,):
            raise ValueError(f"expected position (5, 3) and yaw (3,), got {p.shape}, {y.shape}")
        object.__setattr__(self, "position", _readonly(p))
        object.__setattr__(self, "yaw", _readonly(y))

    @classmethod
    def hover(cls, position: np.ndarray, yaw: float) -> VertexState:
        """At rest at ``position`` (m, shape (3,)) with heading ``yaw`` (rad)."""
        p = np.zeros((POSITION_DERIVS, 3))
        p[0] = position
        return cls(p, np.array([yaw, 0.0, 0.0]))

    @property
    def pose(self) -> np.ndarray:
        """[x, y, z, yaw] (m, rad), shape (4,)."""
        return np.append(self.position[0], self.yaw[0])


@dataclass(frozen=True, eq=False)
class Segment:
    """One 4-D polynomial segment in local time τ ∈ [0, T].

    Attributes
    ----------
    duration : float
        T, s.
    position_coeffs : ndarray, shape (3, 10)
        Per axis, coefficients of increasing powers of τ (m/s^j).
    yaw_coeffs : ndarray, shape (6,)
        Yaw coefficients of increasing powers of τ (rad/s^j).

    Notes
    -----
    Outside [0, T] the segment holds its end points at rest, like
    `mavsysid.vehicle.trajectory.PiecewisePolynomial`, so a segment is a ``Trajectory``.
    """

    duration: float
    position_coeffs: np.ndarray
    yaw_coeffs: np.ndarray

    def __post_init__(self) -> None:
        T = float(self.duration)
        if not T > 0.0 or not np.isfinite(T):
            raise ValueError(f"duration must be positive and finite, got {self.duration}")
        pc = np.array(self.position_coeffs, dtype=float)
        yc = np.array(self.yaw_coeffs, dtype=float)
        if pc.shape != (3, POSITION_COEFFS) or yc.shape != (YAW_COEFFS,):
            raise ValueError(f"expected coefficients (3, 10) and (6,), got {pc.shape}, {yc.shape}")
        object.__setattr__(self, "duration", T)
        object.__setattr__(self, "position_coeffs", _readonly(pc))
        object.__setattr__(self, "yaw_coeffs", _readonly(yc))

    @cached_property
    def unit_coeffs(self) -> tuple[np.ndarray, np.ndarray]:
        """Coefficients in s = τ/T ∈ [0, 1]: position (3, 10) and yaw (6,)."""
        scale = self.duration**POWERS
        return self.position_coeffs * scale, self.yaw_coeffs * scale[:YAW_COEFFS]

    @cached_property
    def derivative_coeffs(self) -> np.ndarray:
        """Rows p, ṗ, p̈, p⃛, p⁗ (x, y, z each), ψ, ψ̇, ψ̈ in powers of s, shape (10, 18).

        Column ``3 k + axis`` (and ``15 + k`` for yaw) holds the coefficients of the k-th
        τ-derivative in increasing powers of s = τ/T, so values are ``s_powers @ D``.
        """
        c = np.concatenate([self.position_coeffs.ravel(), self.yaw_coeffs])
        out = (DERIVATIVE_MAP @ c).reshape(POSITION_COEFFS, -1)
        out *= (self.duration**POWERS)[:, None]
        return out

    def _values(self, s: np.ndarray) -> np.ndarray:
        """All derivatives at unit times s, shape (S, 18)."""
        return (s[:, None] ** POWERS) @ self.derivative_coeffs

    def flat_outputs(self, tau: np.ndarray) -> FlatOutputs:
        """Flat outputs at local times ``tau`` (s, shape (S,)), held at rest outside [0, T]."""
        tau = np.atleast_1d(np.asarray(tau, dtype=float))
        v = self._values(np.clip(tau, 0.0, self.duration) / self.duration)
        outside = (tau < 0.0) | (tau > self.duration)
        if np.any(outside):
            v[outside, 3 : 3 * POSITION_DERIVS] = 0.0
            v[outside, 3 * POSITION_DERIVS + 1 :] = 0.0
        pos = v[:, : 3 * POSITION_DERIVS].reshape(-1, POSITION_DERIVS, 3)
        yaw = v[:, 3 * POSITION_DERIVS :]
        return FlatOutputs(
            pos[:, 0], pos[:, 1], pos[:, 2], pos[:, 3], pos[:, 4], yaw[:, 0], yaw[:, 1], yaw[:, 2]
        )

    def state_at(self, s: float) -> VertexState:
        """Flat state at unit time s = τ/T ∈ [0, 1]."""
        v = self._values(np.array([s]))[0]
        return VertexState(v[: 3 * POSITION_DERIVS].reshape(POSITION_DERIVS, 3),
                           v[3 * POSITION_DERIVS :])

    def start_state(self) -> VertexState:
        """Flat state at τ = 0."""
        return self.state_at(0.0)

    def end_state(self) -> VertexState:
        """Flat state at τ = T."""
        return self.state_at(1.0)


def _trusted_segment(duration: float, position_b: np.ndarray, yaw_b: np.ndarray) -> Segment:
    """Segment from unit-time coefficients (3, 10), (6,) that need no validation.

    The connections call this thousands of times per second; it skips the checks and
    copies of ``Segment.__init__`` (the arrays are fresh and owned by the segment).
    """
    inv = duration ** -POWERS
    seg = object.__new__(Segment)
    object.__setattr__(seg, "duration", duration)
    object.__setattr__(seg, "position_coeffs", _readonly(position_b * inv))
    object.__setattr__(seg, "yaw_coeffs", _readonly(yaw_b * inv[:YAW_COEFFS]))
    return seg


def _start_boundary(start: VertexState, duration: float, n_position: int, n_yaw: int
                    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """T, the powers T^k, and boundary-data arrays (n_position, 3) and (n_yaw,) whose first
    rows hold the start's derivatives in s units (d^k/ds^k = T^k d^k/dτ^k)."""
    T = float(duration)
    if not T > 0.0:
        raise ValueError(f"duration must be positive, got {duration}")
    scale = T**POWERS
    d = np.empty((n_position, 3))
    np.multiply(start.position, scale[:POSITION_DERIVS, None], out=d[:POSITION_DERIVS])
    yd = np.empty(n_yaw)
    np.multiply(start.yaw, scale[:YAW_DERIVS], out=yd[:YAW_DERIVS])
    return T, scale, d, yd


def connect_free_end(start: VertexState, end_position: np.ndarray, end_yaw: float,
                     duration: float) -> Segment:
    """Minimum-snap / minimum-yaw-rate segment with free end derivatives.

    Paper Eq. (min_snap_optimization) with the "free" option: the start is fixed up to
    snap and yaw acceleration, the end only in position and yaw; minimises
    ∫‖d⁴p/dt⁴‖² dt per axis and ∫ψ̇² dt (closed form of Richter et al., 2013).

    Parameters
    ----------
    start : VertexState
        Start flat state.
    end_position : ndarray, shape (3,)
        End position, m, world ENU.
    end_yaw : float
        End yaw, rad. Used as given: the caller chooses its branch (e.g. unwraps a
        sampled yaw next to ``start.yaw[0]``).
    duration : float
        T, s.

    Returns
    -------
    Segment
    """
    T, _, d, yd = _start_boundary(start, duration, POSITION_DERIVS + 1, YAW_DERIVS + 1)
    d[POSITION_DERIVS] = end_position
    yd[YAW_DERIVS] = end_yaw
    return _trusted_segment(T, (POSITION_FREE_END @ d).T, YAW_FREE_END @ yd)


def connect_fixed(start: VertexState, end: VertexState, duration: float) -> Segment:
    """Fully constrained segment: both ends fixed up to snap and yaw acceleration.

    Hermite interpolation, 10 conditions per position axis and 6 in yaw, so the
    polynomial is unique (paper Eq. (min_snap_optimization), end not free).

    Parameters
    ----------
    start, end : VertexState
        Flat states at τ = 0 and τ = T.
    duration : float
        T, s.

    Returns
    -------
    Segment
    """
    T, scale, d, yd = _start_boundary(start, duration, POSITION_COEFFS, YAW_COEFFS)
    np.multiply(end.position, scale[:POSITION_DERIVS, None], out=d[POSITION_DERIVS:])
    np.multiply(end.yaw, scale[:YAW_DERIVS], out=yd[YAW_DERIVS:])
    return _trusted_segment(T, (POSITION_HERMITE @ d).T, YAW_HERMITE @ yd)


def stop_segment(start: VertexState, duration: float,
                 end_position: np.ndarray | None = None) -> Segment:
    """Segment coming to rest: all end derivatives zero.

    Parameters
    ----------
    start : VertexState
        Start flat state.
    duration : float
        T, s.
    end_position : ndarray, shape (3,), optional
        Where to stop, m. By default p₀ + v₀ T / 2, roughly where a smooth stop from
        velocity v₀ ends (a linear decay of the speed covers half of v₀ T).

    Returns
    -------
    Segment
        Ends at rest, yaw held at ψ₀ + ψ̇₀ T / 2 for the same reason.
    """
    T = float(duration)
    if end_position is None:
        end_position = start.position[0] + start.position[1] * (T / 2.0)
    end = VertexState.hover(np.asarray(end_position, dtype=float),
                            start.yaw[0] + start.yaw[1] * (T / 2.0))
    return connect_fixed(start, end, T)


def snap_cost(segment: Segment) -> float:
    """∫₀^T ‖d⁴p/dτ⁴‖² dτ over the segment, m²/s⁷ (exact, from the Q matrix).

    With s = τ/T: ∫₀^T (p⁗)² dτ = T^(-7) ∫₀¹ (d⁴p/ds⁴)² ds = T^(-7) bᵀ Q b.
    """
    b, _ = segment.unit_coeffs
    return float(np.einsum("ai,ij,aj->", b, POSITION_COST, b)) / segment.duration**7


def yaw_rate_cost(segment: Segment) -> float:
    """∫₀^T ψ̇² dτ over the segment, rad²/s (exact, from the Q matrix)."""
    _, b = segment.unit_coeffs
    return float(b @ YAW_COST @ b) / segment.duration


def duration_range(distance: float, speed_max: float, budget_left: float,
                   segment_time_max: float, min_duration: float = 0.0
                   ) -> tuple[float, float] | None:
    """Interval to sample a segment duration from (paper, Section "Motion Planning").

    T ∈ [d / v_max, min(budget left, T_max)].

    Parameters
    ----------
    distance : float
        Euclidean distance d between the vertices, m.
    speed_max : float
        v_max, m/s.
    budget_left : float
        Flight time still available at the start vertex, s (budget minus the least cost
        of its open beliefs).
    segment_time_max : float
        T_max, s.
    min_duration : float, optional
        Extra lower bound, s: the paper's bound is 0 for coincident vertices, and a
        segment needs T > 0.

    Returns
    -------
    tuple of float or None
        ``(lo, hi)`` in s, or None when the interval is empty (or hi ≤ 0).
    """
    lo = max(distance / speed_max, min_duration)
    hi = min(budget_left, segment_time_max)
    if lo > hi or hi <= 0.0:
        return None
    return lo, hi


def to_piecewise(segments: Sequence[Segment]) -> PiecewisePolynomial:
    """Chain segments into one `mavsysid.vehicle.trajectory.PiecewisePolynomial`."""
    return PiecewisePolynomial(np.array([s.duration for s in segments]),
                               np.array([s.position_coeffs for s in segments]),
                               np.array([s.yaw_coeffs for s in segments]))

