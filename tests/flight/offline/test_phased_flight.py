"""Take-off and landing around a calibration part; the exporters' shared helpers."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.autopilot_log import check_motor_order, sample_indices
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.phased_flight import FlightPhases, phased_trajectory


def test_calibration_part_is_flown_between_take_off_and_landing():
    calibration = excitation_trajectory(ExcitationSpec(duration=12.0, ramp=2.0))
    whole, phases = phased_trajectory(calibration, ground_height=0.1, climb_time=3.0,
                                      hover_time=1.5)
    assert whole.duration == pytest.approx(phases.landed)
    assert phases.calibration_end - phases.calibration_start == pytest.approx(12.0)
    ends = whole.flat_outputs(np.array([0.0, whole.duration]))
    np.testing.assert_allclose(ends.position[:, 2], 0.1)
    for derivative in (ends.velocity, ends.acceleration, ends.jerk):
        np.testing.assert_allclose(derivative, 0.0, atol=1e-12)
    tau = np.linspace(0.0, calibration.duration, 301)
    inside = whole.flat_outputs(phases.calibration_start + tau)
    expected = calibration.flat_outputs(tau)
    np.testing.assert_allclose(inside.position, expected.position, atol=1e-9)
    np.testing.assert_allclose(inside.yaw, expected.yaw, atol=1e-9)
    # Continuous up to snap across every knot: no jump in the reference the controller sees.
    dense = np.linspace(0.0, whole.duration, 20001)
    flat = whole.flat_outputs(dense)
    step = dense[1] - dense[0]
    for value, rate in ((flat.position, flat.velocity), (flat.velocity, flat.acceleration),
                        (flat.acceleration, flat.jerk)):
        jumps = np.abs(np.diff(value, axis=0)) - np.abs(rate[:-1]) * step
        assert jumps.max() < 1e-3


def test_calibration_part_below_the_ground_is_refused():
    calibration = excitation_trajectory(ExcitationSpec(duration=12.0, ramp=2.0))
    with pytest.raises(ValueError, match="above the ground"):
        phased_trajectory(calibration, ground_height=5.0)


def test_phases_must_follow_each_other():
    with pytest.raises(ValueError, match="follow"):
        FlightPhases(0.0, 5.0, 4.0, 9.0)


def test_motor_order_must_be_a_permutation():
    np.testing.assert_array_equal(check_motor_order([3, 1, 0, 2], 4), [3, 1, 0, 2])
    for bad in ([0, 1, 2], [0, 1, 1, 2], [1, 2, 3, 4]):
        with pytest.raises(ValueError, match="permutation"):
            check_motor_order(bad, 4)


def test_sample_indices_follow_the_logging_rate():
    t = np.arange(0.0, 10.0, 0.01)
    i = sample_indices(t, 25.0, phase=0.002)
    assert np.diff(t[i]).max() == pytest.approx(0.04)
    assert i.size == pytest.approx(250, abs=1)
    assert t[i[0]] >= 0.002
