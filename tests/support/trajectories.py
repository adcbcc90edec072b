"""Hand-made trajectories for simulated flights, and writing them as trajectory files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["ground_descent", "write_trajectory_json"]


def ground_descent(low: float = 0.1, high: float = 1.5, repeats: int = 2) -> PiecewisePolynomial:
    """Descend from ``high`` to ``low`` m (world z; the ground is z = 0), slide sideways
    0.4 m there, climb back; ``repeats`` times. Rest-to-rest segments of 3 to 4 s.

    With the default ``low`` the Firefly's hubs (0.037 m above its origin) pass within
    one rotor diameter (0.2 m for a 0.1 m radius) of the ground.
    """
    points = [(0.0, 0.0, high)]
    times = [0.0]
    for _ in range(repeats):
        for point, duration in (((0.0, 0.0, low), 4.0), ((0.4, 0.0, low), 3.0),
                                ((0.0, 0.0, low), 3.0), ((0.0, 0.0, high), 4.0)):
            points.append(point)
            times.append(times[-1] + duration)
    knots = np.zeros((len(points), 5, 3))
    knots[:, 0] = points
    return PiecewisePolynomial.from_waypoints(np.array(times), knots,
                                              np.zeros((len(points), 3)))


def write_trajectory_json(path: Path, trajectory: PiecewisePolynomial, config: VehicleConfig,
                          kind: str = "test") -> Path:
    """Write ``trajectory`` as a trajectory file for ``config``; returns ``path``."""
    write_trajectory_file(path, trajectory_file_for(trajectory, config, kind))
    return path
