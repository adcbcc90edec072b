"""The time offset between rotor speeds and pose, from the torque balance.

A pose from an on-board estimator, a motion-capture link or a logger's buffering reaches
the log later than the rotor speeds it results from (or earlier, if the rotor speeds are
the ones filtered). A lag of a few milliseconds is a phase error of several degrees at the
attitude loop's frequencies, which biases the inertia as much as a wrong window does. The
offset δ (the pose lags the rotor speeds by δ) is the one minimising the band-passed
torque balance's normalised residual: a grid over ±`MAX_DELAY` at the coarser of 2 ms and
the sample step, refined by a parabola through the best grid point and its neighbours.
Its σ comes from the balance itself (`mavsysid.estimation.wrench_balance`): the residual
regressed, with the Newey–West covariance, on the model's derivative with respect to δ.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["MAX_DELAY", "scan_delay"]

#: Largest |δ| searched, s: on-board estimators delay their pose by up to about 0.1 s.
MAX_DELAY = 0.1
#: Coarsest grid step, s.
GRID_STEP = 0.002


def scan_delay(objective: Callable[[float], float], dt: float,
               max_delay: float = MAX_DELAY) -> tuple[float, np.ndarray, np.ndarray]:
    """The δ minimising ``objective`` over a grid, refined by a parabola.

    Parameters
    ----------
    objective : callable
        δ (s) → normalised residual (smaller is better; NaN where it cannot be formed).
    dt : float
        Sample interval, s (the grid step is at least this).
    max_delay : float
        Half-width of the grid, s.

    Returns
    -------
    delay : float
        s.
    grid, values : ndarray
        The grid (s) and the objective on it.
    """
    step = max(GRID_STEP, dt)
    grid = np.arange(-max_delay, max_delay + 0.5 * step, step)
    values = np.array([objective(float(d)) for d in grid])
    finite = np.isfinite(values)
    if not finite.any():
        return 0.0, grid, values
    i = int(np.nanargmin(np.where(finite, values, np.inf)))
    if 0 < i < len(grid) - 1 and np.all(finite[i - 1:i + 2]):
        a, b, c = values[i - 1:i + 2]
        curvature = a - 2.0 * b + c
        if curvature > 0.0:
            return float(grid[i] + 0.5 * step * (a - c) / curvature), grid, values
    return float(grid[i]), grid, values
