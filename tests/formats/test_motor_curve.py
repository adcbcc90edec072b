"""The motor curve n = n_max · sqrt((1 − e) u + e u²) and its PWM mapping."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.formats.motor_curve import (
    check_curve_against_rpm,
    check_pwm_outputs,
    fit_curve_scale,
    pwm_from_rotor_speed,
    rotor_speed_from_pwm,
    rotor_speed_from_throttle,
    throttle_from_pwm,
)
from mavsysid.formats.parsed_log import Series
from mavsysid.vehicle.config import VehicleConfig, load_vehicle

from mavsysid.errors import LogFormatError


@pytest.mark.parametrize(("u", "expo", "expected"), [
    (0.0, 0.65, 0.0),
    (1.0, 0.65, 1.0),
    (0.25, 0.0, 0.5),  # linear thrust: n ∝ sqrt(u)
    (0.25, 1.0, 0.25),  # quadratic thrust: n ∝ u
    (0.5, 0.65, np.sqrt(0.35 * 0.5 + 0.65 * 0.25)),
    (1.7, 0.65, 1.0),  # clipped
])
def test_rotor_speed_from_throttle(u: float, expo: float, expected: float) -> None:
    """The curve gives n_max · sqrt((1 − e) u + e u²) with u clipped to [0, 1]."""
    assert rotor_speed_from_throttle(np.array(u), 800.0, expo) == pytest.approx(800.0 * expected)


@pytest.mark.parametrize(("pwm", "u"), [(0.0, 0.0), (900.0, 0.0), (1000.0, 0.0), (1250.0, 0.25),
                                        (2000.0, 1.0), (2100.0, 1.0)])
def test_throttle_from_pwm(pwm: float, u: float) -> None:
    """PWM maps linearly onto [0, 1] between pwm_min and pwm_max, clipped outside."""
    assert throttle_from_pwm(np.array(pwm), 1000.0, 2000.0) == pytest.approx(u)


def test_rotor_speed_from_pwm_uses_the_vehicle_curve(firefly: VehicleConfig) -> None:
    """The vehicle's [motor] defaults give 0 at 1000 µs, n_max at 2000 µs, increasing between."""
    pwm = np.linspace(1000.0, 2000.0, 101)
    n = rotor_speed_from_pwm(pwm, firefly)
    assert n[0] == 0.0 and n[-1] == pytest.approx(firefly.limits.rotor_speed_max)
    assert (np.diff(n) > 0).all()


def test_pwm_is_the_inverse_of_the_readers_motor_curve():
    vehicle = load_vehicle("quad_x")
    n = np.random.default_rng(2).uniform(0.0, vehicle.limits.rotor_speed_max, (50, 4))
    np.testing.assert_allclose(rotor_speed_from_pwm(pwm_from_rotor_speed(n, vehicle), vehicle),
                               n, rtol=1e-9, atol=1e-6)


def test_pwm_outputs_in_range_pass_and_others_are_refused(firefly: VehicleConfig) -> None:
    """Armed PWM (zeros while disarmed) passes; a mixer's 0..1 or a 12-bit scale do not."""
    low, high = firefly.motor.pwm_min, firefly.motor.pwm_max
    rng = np.random.default_rng(5)
    pwm = rng.uniform(low + 0.1 * (high - low), high, size=(500, 4))
    pwm[:50] = 0.0
    check_pwm_outputs(pwm, firefly, "log.tlog: SERVO_OUTPUT_RAW")
    for outputs in (pwm / high, 4.095 * (pwm - low)):
        with pytest.raises(LogFormatError, match=r"^log\.tlog: SERVO_OUTPUT_RAW: the motor "
                           r"outputs are not PWM in the vehicle's \[motor\] range"):
            check_pwm_outputs(outputs, firefly, "log.tlog: SERVO_OUTPUT_RAW")


def test_commanded_speeds_are_checked_against_sparse_esc_rpm() -> None:
    """ESC rpm at 3 Hz beside outputs at 100 Hz: a curve within 15 % of it passes; one 20 ×
    off (DroneCAN commands read as PWM through a PWM curve) is refused in one line."""
    t = np.arange(0.0, 10.0, 0.01)
    n = 400.0 + 50.0 * np.sin(t)[:, None] * np.array([1.0, -1.0, 1.0, -1.0])
    commanded = Series(t, n, "actuator_outputs PWM")
    slow = np.arange(0.05, 10.0, 0.3)
    esc = Series(slow, 1.1 * (400.0 + 50.0 * np.sin(slow)[:, None]
                              * np.array([-1.0, 1.0, -1.0, 1.0])), "esc_status rpm")
    check_curve_against_rpm(commanded, esc, "log.ulg: actuator_outputs against esc_status")
    far = Series(slow, 20.0 * esc.values, "esc_status rpm")
    with pytest.raises(LogFormatError, match=r"^log\.ulg: actuator_outputs against esc_status: "
                       r"the motor curve's rotor speeds are 0\.04\d+ × what the log's own ESC"):
        check_curve_against_rpm(commanded, far, "log.ulg: actuator_outputs against esc_status")


def test_the_curve_scale_fitted_to_noisy_sparse_esc_rpm_covers_the_truth() -> None:
    """ESC rpm at 3 Hz, 1 % noise, 8 % faster than the curve: the fitted scale lies within
    3 σ of 1.08 on 200 seeded flights, and its σ is no wider than a few times the spread."""
    t = np.arange(0.0, 20.0, 0.01)
    n = 400.0 + 50.0 * np.sin(t)[:, None] * np.array([1.0, -1.0, 1.0, -1.0])
    commanded = Series(t, n, "actuator_outputs PWM")
    slow = np.arange(0.05, 20.0, 0.3)
    clean = 1.08 * (400.0 + 50.0 * np.sin(slow)[:, None] * np.array([1.0, -1.0, 1.0, -1.0]))
    rng = np.random.default_rng(11)
    z = []
    for _ in range(200):
        esc = Series(slow, clean * (1.0 + 0.01 * rng.standard_normal(clean.shape)), "rpm")
        fit = fit_curve_scale(commanded, esc)
        assert fit is not None and fit.samples == slow.size
        z.append((fit.factor - 1.08) / fit.sigma)
    z = np.abs(np.array(z))
    assert np.mean(z < 3.0) > 0.97
    assert np.median(z) > 0.2  # a σ far too wide would put every flight near 0
    assert fit_curve_scale(commanded, Series(slow[:2], clean[:2], "rpm")) is None
