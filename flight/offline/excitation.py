"""The built-in excitation trajectory: a smooth 3-D Lissajous figure with yaw oscillation.

Each axis follows c + A cos(ω τ) and yaw Ψ sin(ω_ψ τ). The frequencies are rounded
down to whole numbers of periods over the oscillating window, so the figure closes on
itself and the ramps into and out of hover are mirror images; a longer or shorter flight
keeps the same frequencies (and so the same aggressiveness) with more or fewer periods.
The figure is stored as the paper's polynomial segments (position N = 10, yaw N = 6,
Hermite-matched up to snap and yaw acceleration at each knot), so it can be exported and
streamed like a planned one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["ExcitationSpec", "excitation_trajectory"]


@dataclass(frozen=True)
class ExcitationSpec:
    """Shape of the excitation figure.

    Attributes
    ----------
    duration : float
        Total duration including both ramps, s.
    ramp : float
        Duration of the ramp from hover into the figure (and back), s.
    center : tuple of 3 float
        Centre of the figure, m, world ENU.
    amplitude : tuple of 3 float
        Half-extent per axis, m.
    frequency : tuple of 3 float
        Target angular frequency per axis, rad/s (rounded down to whole periods).
    yaw_amplitude : float
        Yaw half-extent, rad.
    yaw_frequency : float
        Target yaw angular frequency, rad/s (rounded down to whole periods).
    knot_spacing : float
        Target segment duration inside the figure, s.
    """

    duration: float = 30.0
    ramp: float = 3.0
    center: tuple[float, float, float] = (0.0, 0.0, 1.5)
    amplitude: tuple[float, float, float] = (1.3, 1.0, 0.4)
    frequency: tuple[float, float, float] = (1.571, 1.833, 1.309)
    yaw_amplitude: float = 0.7
    yaw_frequency: float = 1.047
    knot_spacing: float = 1.0


def excitation_trajectory(spec: ExcitationSpec | None = None) -> PiecewisePolynomial:
    """Build the excitation trajectory as polynomial segments.

    Parameters
    ----------
    spec : ExcitationSpec, optional
        Centre, amplitudes, frequencies and duration (default: the built-in figure).

    Returns
    -------
    PiecewisePolynomial
        Starts and ends at rest at ``center + amplitude`` with yaw 0.
    """
    spec = spec or ExcitationSpec()
    window = spec.duration - 2.0 * spec.ramp
    if window <= 0.0:
        raise ValueError("duration must exceed twice the ramp time")
    n_seg = max(1, round(window / spec.knot_spacing))
    tau = np.linspace(0.0, window, n_seg + 1)
    omega = _whole_periods(np.asarray(spec.frequency, dtype=float), window)
    amp = np.asarray(spec.amplitude, dtype=float)
    center = np.asarray(spec.center, dtype=float)
    w_psi = float(_whole_periods(np.array([spec.yaw_frequency]), window)[0])

    # d^m/dτ^m cos(ωτ) = ω^m cos(ωτ + mπ/2); likewise for sin.
    pos = np.empty((tau.size, 5, 3))
    for m in range(5):
        pos[:, m, :] = amp * omega**m * np.cos(np.outer(tau, omega) + m * math.pi / 2.0)
    pos[:, 0, :] += center
    yaw = np.empty((tau.size, 3))
    for m in range(3):
        yaw[:, m] = spec.yaw_amplitude * w_psi**m * np.sin(w_psi * tau + m * math.pi / 2.0)

    rest_pos = np.zeros((1, 5, 3))
    rest_pos[0, 0] = center + amp
    rest_yaw = np.zeros((1, 3))
    times = np.concatenate([[0.0], spec.ramp + tau, [spec.duration]])
    return PiecewisePolynomial.from_waypoints(
        times,
        np.concatenate([rest_pos, pos, rest_pos]),
        np.concatenate([rest_yaw, yaw, rest_yaw]),
    )


def _whole_periods(omega: np.ndarray, window: float) -> np.ndarray:
    """The highest angular frequencies ≤ ``omega`` with a whole number of periods (≥ 1).

    Rounding down keeps a shorter figure from becoming more aggressive than the target.
    """
    cycles = np.maximum(1, np.floor(omega * window / (2.0 * math.pi) + 1e-9))
    return 2.0 * math.pi * cycles / window
