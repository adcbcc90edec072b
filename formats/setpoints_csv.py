"""Sampled setpoints of a trajectory as CSV: ``t,x,y,z,vx,vy,vz,ax,ay,az,yaw,yaw_rate``.

What ``mavsysid plan --csv`` writes next to the trajectory file
(`mavsysid.formats.trajectory_file`), for tools that want samples rather than polynomials
(docs/architecture.md).
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
from mavsysid.vehicle.trajectory import Trajectory

from mavsysid.errors import InputError

__all__ = ["SETPOINT_COLUMNS", "write_setpoints_csv"]

#: Header of the sampled-setpoint CSV (world ENU, SI).
SETPOINT_COLUMNS: tuple[str, ...] = ("t", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az",
                                     "yaw", "yaw_rate")


def write_setpoints_csv(path: str | Path, trajectory: Trajectory, rate: float = 100.0) -> None:
    """Write sampled setpoints ``t,x,y,z,vx,vy,vz,ax,ay,az,yaw,yaw_rate`` (world ENU, SI).

    Parameters
    ----------
    path : str or Path
        The CSV to write, atomically (its directory is created).
    trajectory : Trajectory
        Anything with ``duration`` and ``flat_outputs`` (a `PiecewisePolynomial`).
    rate : float
        Sample rate, Hz. Rows at t = k / rate from 0, plus a last row at the exact
        duration when it is not on the grid, so the final hover is always included.

    Notes
    -----
    Yaw is the trajectory's continuous yaw, not wrapped to (−π, π]. Values are written
    with 6 decimals (µm, µrad).
    """
    if not (math.isfinite(rate) and rate > 0.0):
        raise InputError(f"setpoint rate: a positive number of Hz, got {rate!r}")
    duration = trajectory.duration
    t = np.arange(math.floor(duration * rate + 1e-9) + 1) / rate
    if duration - t[-1] > 1e-9:
        t = np.append(t, duration)
    flat = trajectory.flat_outputs(t)
    table = np.column_stack([t, flat.position, flat.velocity, flat.acceleration,
                             flat.yaw, flat.yaw_rate])
    # Adding 0.0 after rounding turns -0.0 into 0.0, which reads better in a CSV.
    table = np.round(table, 6) + 0.0
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            np.savetxt(f, table, fmt="%.6f", delimiter=",", header=",".join(SETPOINT_COLUMNS),
                       comments="")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
