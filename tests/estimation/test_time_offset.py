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
