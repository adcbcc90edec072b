"""Tests of the sampled-setpoint CSV."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.setpoints_csv import SETPOINT_COLUMNS, write_setpoints_csv
from mavsysid.vehicle.trajectory import PiecewisePolynomial


def test_setpoint_csv_header_and_samples(tmp_path):
    """Exact header; rows every 10 ms from 0 to the duration inclusive; values as flat outputs."""
    figure = excitation_trajectory(ExcitationSpec(duration=12.0))
    path = tmp_path / "setpoints.csv"
    write_setpoints_csv(path, figure)
    lines = path.read_text().splitlines()
    assert lines[0] == "t,x,y,z,vx,vy,vz,ax,ay,az,yaw,yaw_rate"
    assert lines[0].split(",") == list(SETPOINT_COLUMNS)
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    assert table.shape == (1201, 12)
    np.testing.assert_allclose(table[:, 0], np.arange(1201) / 100.0, atol=1e-9)
    flat = figure.flat_outputs(table[:, 0])
    expected = np.column_stack([flat.position, flat.velocity, flat.acceleration, flat.yaw,
                                flat.yaw_rate])
    np.testing.assert_allclose(table[:, 1:], expected, atol=6e-7)


def test_setpoint_csv_ends_at_the_exact_duration(tmp_path):
    """A duration off the 100 Hz grid still gets a last row at the end of the flight."""
    start = np.zeros((2, 5, 3))
    start[1, 0] = [1.0, 0.0, 0.0]
    line = PiecewisePolynomial.from_waypoints(np.array([0.0, 1.234]), start, np.zeros((2, 3)))
    path = tmp_path / "s.csv"
    write_setpoints_csv(path, line, rate=100.0)
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    assert table.shape[0] == 125
    assert table[-1, 0] == pytest.approx(1.234) and table[-1, 1] == pytest.approx(1.0)
