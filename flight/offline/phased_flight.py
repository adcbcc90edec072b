"""A whole flight as a pilot flies one: take-off, the calibration part, landing.

Real autopilot logs hold more than the calibration part: the vehicle climbs from the
ground, hovers while the operator switches to the calibration mode, flies the
calibration trajectory, hovers again and lands. `phased_trajectory` wraps a calibration
trajectory in such a flight, as one trajectory the offline simulator flies from rest
(vertical climb and descent, rest to rest, continuous up to snap), and says when each
phase starts, so an exporter can write the autopilot's mode changes at those times.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["FlightPhases", "phased_trajectory"]


@dataclass(frozen=True)
class FlightPhases:
    """When each phase of a flight starts and ends, s on the trajectory's clock.

    Attributes
    ----------
    takeoff : float
        Start of the climb (motors spinning on the ground), s.
    calibration_start, calibration_end : float
        The calibration part: where the operator hands over to the calibration mode
        (ArduPilot GUIDED, PX4 OFFBOARD) and where the landing mode is selected, s.
    landed : float
        End of the descent, s.
    """

    takeoff: float
    calibration_start: float
    calibration_end: float
    landed: float

    def __post_init__(self) -> None:
        times = (self.takeoff, self.calibration_start, self.calibration_end, self.landed)
        if not all(a < b for a, b in itertools.pairwise(times)):
            raise ValueError(f"flight phases must follow each other, got {times}")


def _rest_segment(start: np.ndarray, end: np.ndarray, yaw: float,
                  duration: float) -> PiecewisePolynomial:
    """A straight move from rest at ``start`` to rest at ``end`` (m, ENU) at constant yaw."""
    position = np.zeros((2, 5, 3))
    position[0, 0], position[1, 0] = start, end
    yaw_derivs = np.zeros((2, 3))
    yaw_derivs[:, 0] = yaw
    return PiecewisePolynomial.from_waypoints(np.array([0.0, duration]), position, yaw_derivs)


def _padded(coeffs: np.ndarray, size: int) -> np.ndarray:
    """Coefficients in increasing powers, zero-padded along the last axis to ``size``."""
    pad = [(0, 0)] * (coeffs.ndim - 1) + [(0, size - coeffs.shape[-1])]
    return np.pad(coeffs, pad)


def _concatenate(parts: list[PiecewisePolynomial]) -> PiecewisePolynomial:
    """One trajectory flying ``parts`` one after the other (each in its local time)."""
    n_pos = max(p.position_coeffs.shape[-1] for p in parts)
    n_yaw = max(p.yaw_coeffs.shape[-1] for p in parts)
    return PiecewisePolynomial(
        np.concatenate([p.durations for p in parts]),
        np.concatenate([_padded(p.position_coeffs, n_pos) for p in parts]),
        np.concatenate([_padded(p.yaw_coeffs, n_yaw) for p in parts]),
    )


def phased_trajectory(calibration: PiecewisePolynomial, ground_height: float = 0.0,
                      climb_time: float = 4.0,
                      hover_time: float = 2.0) -> tuple[PiecewisePolynomial, FlightPhases]:
    """Wrap a calibration trajectory in a take-off before it and a landing after it.

    Parameters
    ----------
    calibration : PiecewisePolynomial
        The calibration part; it must start and end at rest (planned and built-in
        excitation trajectories do).
    ground_height : float
        z of the ground, m (world ENU): where the climb starts and the descent ends.
    climb_time : float
        Duration of the vertical climb and of the descent, s.
    hover_time : float
        Hover before and after the calibration part, s; the mode changes happen at its
        end and at its start respectively.

    Returns
    -------
    trajectory : PiecewisePolynomial
        The whole flight, from rest on the ground to rest on the ground.
    phases : FlightPhases
        Its phase times, s.

    Raises
    ------
    ValueError
        The calibration part starts or ends below the ground, or a non-positive duration.
    """
    if climb_time <= 0.0 or hover_time <= 0.0:
        raise ValueError("climb and hover times must be positive")
    ends = calibration.flat_outputs(np.array([0.0, calibration.duration]))
    start, end = ends.position
    if min(start[2], end[2]) <= ground_height:
        raise ValueError(f"the calibration part must fly above the ground at z = "
                         f"{ground_height:g} m, it starts at {start[2]:g} m and ends at "
                         f"{end[2]:g} m")
    ground_start = np.array([start[0], start[1], ground_height])
    ground_end = np.array([end[0], end[1], ground_height])
    yaw0, yaw1 = float(ends.yaw[0]), float(ends.yaw[1])
    parts = [
        _rest_segment(ground_start, start, yaw0, climb_time),
        _rest_segment(start, start, yaw0, hover_time),
        calibration,
        _rest_segment(end, end, yaw1, hover_time),
        _rest_segment(end, ground_end, yaw1, climb_time),
    ]
    calibration_start = climb_time + hover_time
    calibration_end = calibration_start + calibration.duration
    phases = FlightPhases(takeoff=0.0, calibration_start=calibration_start,
                          calibration_end=calibration_end,
                          landed=calibration_end + hover_time + climb_time)
    return _concatenate(parts), phases
