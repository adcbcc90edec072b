"""The grid search for the rotor-to-pose offset, refined below the grid step."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.balance.choices import GRID_STEP, MAX_DELAY, scan_delay


@pytest.mark.parametrize("true", [-0.0473, 0.0, 0.0081, 0.0612])
def test_scan_finds_the_minimum_between_grid_points(true):
    """A smooth objective's minimum is found to a small fraction of the grid step."""
    delay, grid, values = scan_delay(lambda d: (d - true) ** 2 + 1.0, 0.002)
    assert abs(delay - true) < 0.05 * GRID_STEP
    assert grid[0] == pytest.approx(-MAX_DELAY) and len(values) == len(grid)


def test_scan_skips_where_the_objective_cannot_be_formed():
    """NaN values are ignored; all NaN gives 0."""
    delay, _, _ = scan_delay(lambda d: np.nan if d < 0 else (d - 0.03) ** 2, 0.002)
    assert delay == pytest.approx(0.03, abs=1e-4)
    assert scan_delay(lambda d: np.nan, 0.002)[0] == 0.0


@pytest.mark.parametrize(("frequency", "true", "most"), [
    (1.8, 0.0131, 20), (5.0, -0.0437, 20), (12.0, 0.071, 30), (30.0, -0.0052, 60)])
def test_coarse_scan_finds_the_whole_grids_offset_in_fewer_evaluations(frequency, true, most):
    """A torque-like objective with minima a period apart: stepping an eighth of the period
    first gives the whole grid's δ exactly, with far fewer evaluations than its 101."""
    def objective(d: float) -> float:
        return 1.0 - np.cos(2 * np.pi * frequency * (d - true)) * np.exp(-3.0 * abs(d - true))

    evaluations: list[float] = []

    def counted(d: float) -> float:
        evaluations.append(d)
        return objective(d)

    whole, grid, _ = scan_delay(objective, 0.002)
    coarse, _, values = scan_delay(counted, 0.002, coarse=0.125 / frequency)
    assert coarse == whole
    assert len(evaluations) <= most < len(grid)
    assert np.sum(np.isfinite(values)) == len(set(evaluations))
