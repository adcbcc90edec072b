"""Flat-output trajectories: position and yaw with their derivatives over time.

A trajectory is anything with a ``duration`` and a vectorised ``flat_outputs(t)``.
`PiecewisePolynomial` is the paper's representation (Section "Motion Planning"):
4-D segments, position with N = 10 coefficients (continuity up to snap) and yaw with
N = 6 (continuity up to yaw acceleration). Outside [0, duration] a trajectory holds
its end points at rest (zero derivatives).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import factorial
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = [
    "FlatOutputs",
    "PiecewisePolynomial",
    "Trajectory",
    "hermite_coefficients",
    "polynomial_basis",
]


@dataclass(frozen=True)
class FlatOutputs:
    """The flat state of paper Eq. (flat_state) at S sample times.

    Attributes
    ----------
    position, velocity, acceleration, jerk, snap : ndarray, shape (S, 3)
        World ENU, m and its time derivatives (m/s … m/s⁴).
    yaw, yaw_rate, yaw_acceleration : ndarray, shape (S,)
        Yaw ψ (rad, ENU: from x_W towards y_W) and its derivatives.
    """

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    snap: np.ndarray
    yaw: np.ndarray
    yaw_rate: np.ndarray
    yaw_acceleration: np.ndarray

    def __len__(self) -> int:
        return self.position.shape[0]


@runtime_checkable
class Trajectory(Protocol):
    """What the controller, simulator and streamer need from a reference trajectory."""

    @property
    def duration(self) -> float:
        """Length of the trajectory, s."""
        ...

    def flat_outputs(self, t: np.ndarray) -> FlatOutputs:
        """Flat outputs at times ``t`` (s, shape (S,)).

        Parameters
        ----------
        t : ndarray, shape (S,)
            Times, s.
        """
        ...


def polynomial_basis(tau: np.ndarray, n_coeffs: int, derivative: int) -> np.ndarray:
    """Rows d^k/dτ^k [1, τ, …, τ^(N-1)], shape (S, N), for k = ``derivative``.

    Parameters
    ----------
    tau : ndarray, shape (S,)
        Local times.
    n_coeffs : int
        Coefficients per polynomial, N.
    derivative : int
        Order k of the derivative.
    """
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    j = np.arange(n_coeffs)
    factor = np.array(
        [factorial(i) / factorial(i - derivative) if i >= derivative else 0.0 for i in j]
    )
    power = np.clip(j - derivative, 0, None)
    return factor * tau[:, None] ** power


def hermite_coefficients(start: np.ndarray, end: np.ndarray, duration: float) -> np.ndarray:
    """Polynomial matching m derivatives at both ends of a segment.

    Parameters
    ----------
    start, end : ndarray, shape (m, ...)
        Value and first m-1 derivatives at τ = 0 and τ = ``duration`` (trailing
        dimensions are independent axes).
    duration : float
        Segment duration, s.

    Returns
    -------
    ndarray, shape (..., 2m)
        Coefficients in increasing powers of local time τ.
    """
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    m = start.shape[0]
    rows = [polynomial_basis(np.array([0.0]), 2 * m, d)[0] for d in range(m)]
    rows += [polynomial_basis(np.array([duration]), 2 * m, d)[0] for d in range(m)]
    rhs = np.concatenate([start, end], axis=0).reshape(2 * m, -1)
    coeffs = np.linalg.solve(np.array(rows), rhs)
    return np.moveaxis(coeffs.reshape(2 * m, *start.shape[1:]), 0, -1)


@dataclass(frozen=True)
class PiecewisePolynomial:
    """A sequence of 4-D polynomial segments.

    Attributes
    ----------
    durations : ndarray, shape (M,)
        Segment durations, s.
    position_coeffs : ndarray, shape (M, 3, N)
        Position coefficients per segment and axis, increasing powers of local time.
    yaw_coeffs : ndarray, shape (M, Ny)
        Yaw coefficients per segment, increasing powers of local time.
    """

    durations: np.ndarray
    position_coeffs: np.ndarray
    yaw_coeffs: np.ndarray

    def __post_init__(self) -> None:
        d = np.asarray(self.durations, dtype=float)
        if d.ndim != 1 or d.size == 0 or np.any(d <= 0.0):
            raise ValueError("durations must be a non-empty 1-D array of positive values")
        pc = np.asarray(self.position_coeffs, dtype=float)
        yc = np.asarray(self.yaw_coeffs, dtype=float)
        if pc.shape[:2] != (d.size, 3) or yc.shape[0] != d.size or yc.ndim != 2:
            raise ValueError(
                f"coefficient shapes {pc.shape}, {yc.shape} do not match {d.size} segments"
            )
        object.__setattr__(self, "durations", d)
        object.__setattr__(self, "position_coeffs", pc)
        object.__setattr__(self, "yaw_coeffs", yc)

    @property
    def duration(self) -> float:
        """Total duration, s."""
        return float(np.sum(self.durations))

    @property
    def segment_starts(self) -> np.ndarray:
        """Start time of each segment, s, shape (M,)."""
        return np.concatenate([[0.0], np.cumsum(self.durations)[:-1]])

    def _locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        inside = (t >= 0.0) & (t <= self.duration)
        tc = np.clip(t, 0.0, self.duration)
        starts = self.segment_starts
        idx = np.clip(np.searchsorted(starts, tc, side="right") - 1, 0, starts.size - 1)
        return idx, tc - starts[idx], inside

    def flat_outputs(self, t: np.ndarray) -> FlatOutputs:
        """Flat outputs at times ``t`` (s, shape (S,)).

        Parameters
        ----------
        t : ndarray, shape (S,)
            Times, s.
        """
        idx, tau, inside = self._locate(t)
        pc = self.position_coeffs[idx]
        yc = self.yaw_coeffs[idx]
        held = inside[:, None].astype(float)

        def pos(d: int) -> np.ndarray:
            value = np.einsum("sj,saj->sa", polynomial_basis(tau, pc.shape[-1], d), pc)
            return value if d == 0 else value * held

        def yaw(d: int) -> np.ndarray:
            value = np.einsum("sj,sj->s", polynomial_basis(tau, yc.shape[-1], d), yc)
            return value if d == 0 else value * held[:, 0]

        return FlatOutputs(pos(0), pos(1), pos(2), pos(3), pos(4), yaw(0), yaw(1), yaw(2))

    @classmethod
    def from_waypoints(
        cls, times: np.ndarray, position_derivs: np.ndarray, yaw_derivs: np.ndarray
    ) -> PiecewisePolynomial:
        """Hermite segments through knots with given derivatives.

        Parameters
        ----------
        times : ndarray, shape (M+1,)
            Knot times, s, strictly increasing.
        position_derivs : ndarray, shape (M+1, 5, 3)
            Position, velocity, acceleration, jerk and snap at each knot.
        yaw_derivs : ndarray, shape (M+1, 3)
            Yaw, yaw rate and yaw acceleration at each knot.
        """
        times = np.asarray(times, dtype=float)
        durations = np.diff(times)
        pos = [hermite_coefficients(position_derivs[i], position_derivs[i + 1], T)
               for i, T in enumerate(durations)]
        yaw = [hermite_coefficients(yaw_derivs[i], yaw_derivs[i + 1], T)
               for i, T in enumerate(durations)]
        return cls(durations, np.array(pos), np.array(yaw))
