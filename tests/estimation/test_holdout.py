"""The held-out RMSE ratios: pooled per group, fitted model over prior."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.estimation.results import HoldoutCheck


def test_group_ratios_pool_the_axes():
    """Force and torque ratios are the pooled RMSE ratios; overall their geometric mean."""
    h = HoldoutCheck(0.0, np.array([1.0, 1.0, 2.0, 0.1, 0.1, np.nan]),
                     np.array([2.0, 2.0, 4.0, 0.4, 0.2, np.nan]), 100)
    assert h.force_ratio == pytest.approx(0.5)
    assert h.torque_ratio == pytest.approx(np.sqrt(0.02 / 0.2))
    assert h.overall_ratio == pytest.approx(np.sqrt(h.force_ratio * h.torque_ratio))
    d = h.as_dict()
    assert d["axes"]["dw_z"]["ratio"] is None and d["rows"] == 100


def test_overall_ratio_without_torque_axes_is_the_force_ratio():
    """No torque band: the overall ratio is the force ratio alone."""
    h = HoldoutCheck(0.0, np.array([1.0, 1.0, 1.0, np.nan, np.nan, np.nan]),
                     np.array([1.0, 2.0, 2.0, np.nan, np.nan, np.nan]), 10)
    assert np.isnan(h.torque_ratio)
    assert h.overall_ratio == pytest.approx(h.force_ratio)
