"""The shipped ArduCopter SITL quad (vehicle/configs/sitl_quad.toml) against SITL's source.

The constants below are ArduPilot's, at 90700977c553d2dfd95a305acf1c3e098e4d9477 (the build
of ../shared/sitl), with their file and line; the config's values must be what
docs/vehicles/sitl_quad.md derives from them. No SITL is run here (bench/sitl_reference.py
flies it).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from mavsysid.formats.parameter_file import read_parameter_file
from mavsysid.vehicle.config import GRAVITY, SHIPPED_VEHICLES, VehicleConfig, load_vehicle
from mavsysid.vehicle.mav_model import rotor_speed_for_thrust
from mavsysid.vehicle.motor_order import AUTOPILOT_FRAMES, output_to_rotor

PARMS = Path(__file__).resolve().parents[2] / "vehicle" / "configs" / "sitl_quad.parm"

# libraries/SITL/SIM_Frame.h (struct Model).
MASS = 3.0  # :85
DIAGONAL_SIZE = 0.35  # :88
REF_ALTITUDE = 593.0  # :97, refAlt
HOVER_THROTTLE = 0.39  # :108, hoverThrOut
PROP_EXPO = 0.65  # :111, propExpo
PWM_MIN, PWM_MAX, SPIN_MIN, SPIN_MAX = 1000.0, 2000.0, 0.15, 0.95  # :118-124
DISC_AREA = 0.385  # :131
MOMENTUM_DRAG_COEF = 0.2  # :134, mdrag_coef
# SITL's gravity, GRAVITY_MSS (libraries/AP_Math/definitions.h:44); mavsysid's is 9.81.
SITL_GRAVITY = 9.80665
# The config's reference height, m AMSL (its comments): the README home 488 m + 2 m.
ALTITUDE = 490.0


def _air_density(alt_amsl: float) -> float:
    """Air density, kg/m³: ArduPilot's 1976 atmosphere below 11 km
    (libraries/AP_Baro/AP_Baro_atmosphere.cpp:211-230)."""
    radius, r_specific, lapse = 6356.766e3, 287.053072, -6.5e-3
    h = radius * alt_amsl / (radius + alt_amsl)
    temp = 320.650 + lapse * (h + 5000.0)
    return 1.930467 * (temp / 320.650) ** (-(SITL_GRAVITY / (lapse * r_specific) + 1.0))


def _thrust_fraction(c: float) -> float:
    """SITL's thrust over its full-command thrust at command c (SIM_Motor.cpp:217-218)."""
    return (1.0 - PROP_EXPO) * c + PROP_EXPO * c * c


@pytest.fixture(scope="module")
def sitl_quad() -> VehicleConfig:
    return load_vehicle("sitl_quad")


def test_is_shipped_and_names_its_autopilot_frame(sitl_quad: VehicleConfig) -> None:
    """`--vehicle sitl_quad` loads, and its rotors are ArduPilot's quad X outputs 1–4 in order."""
    assert "sitl_quad" in SHIPPED_VEHICLES
    assert sitl_quad.source == "builtin:sitl_quad"
    assert sitl_quad.autopilot_frame == "ardupilot:quad_x"
    order = output_to_rotor(sitl_quad.rotor_positions, sitl_quad.rotor_directions,
                            sitl_quad.autopilot_frame)
    assert order == (0, 1, 2, 3)


def test_parameter_file_sets_the_frame_the_config_names() -> None:
    """sitl_quad.parm flies ArduCopter as an X (FRAME_CLASS 1 is copter.parm's) without ESC rpm."""
    parms = read_parameter_file(PARMS)
    assert parms["FRAME_TYPE"] == 1.0  # MOTOR_FRAME_TYPE_X, AP_MotorsMatrix.cpp:591
    assert parms["SIM_ESC_TELEM"] == 0.0


@pytest.mark.parametrize(("c", "a", "b"), [(2, 0, 1), (0, 1, 2), (1, 2, 0)])
def test_inertia_satisfies_the_triangle_inequality(sitl_quad: VehicleConfig, c: int, a: int,
                                                   b: int) -> None:
    """j_a + j_b ≥ j_c for every axis, without slack (SITL's ring makes j_x + j_y = j_z)."""
    j = sitl_quad.parameters.J
    assert j[a] + j[b] >= j[c] * (1.0 - 1e-12)


def test_inertia_is_sitl_ring_estimate(sitl_quad: VehicleConfig) -> None:
    """J is SIM_Frame.cpp:603-608's half mass on a ring of radius diagonal_size / 2."""
    ring = MASS * (DIAGONAL_SIZE / 2.0) ** 2
    assert sitl_quad.mass == MASS
    np.testing.assert_allclose(sitl_quad.parameters.J, [ring / 4, ring / 4, ring / 2], rtol=1e-12)


def test_rotors_sit_at_the_diagonal_size_with_sitl_spins(sitl_quad: VehicleConfig) -> None:
    """Motor i at diagonal_size from the centre (SIM_Motor.cpp:188-189), angle and spin of
    SIM_Frame.cpp:42-45 (SITL's own quad_x table, which must agree with the autopilot's)."""
    angles = [45.0, -135.0, -45.0, 135.0]  # degrees clockwise from the nose
    spins = [1, 1, -1, -1]  # AP_MOTORS_MATRIX_YAW_FACTOR_CCW = 1, CW = -1
    for rotor, angle, spin in zip(sitl_quad.rotors, angles, spins, strict=True):
        a = math.radians(angle)
        expected = [DIAGONAL_SIZE * math.cos(a), -DIAGONAL_SIZE * math.sin(a), 0.0]
        np.testing.assert_allclose(rotor.position, expected, atol=1e-12)
        assert rotor.direction == spin
    frame = AUTOPILOT_FRAMES["ardupilot:quad_x"]
    assert [r.angle_deg for r in frame] == angles and [r.direction for r in frame] == spins


def test_motor_curve_is_sitl_pwm_to_command(sitl_quad: VehicleConfig) -> None:
    """[motor] maps PWM to SITL's command c (SIM_Motor.cpp:204-210) with its expo, no lag."""
    motor = sitl_quad.motor
    assert motor.pwm_min == PWM_MIN + SPIN_MIN * (PWM_MAX - PWM_MIN)
    assert motor.pwm_max == PWM_MIN + SPIN_MAX * (PWM_MAX - PWM_MIN)
    assert motor.thrust_expo == PROP_EXPO
    assert motor.time_constant == 0.0


def test_full_command_thrust_is_sitl(sitl_quad: VehicleConfig) -> None:
    """c_T n_max² is SITL's full-command thrust m g / (4 hoverThrOut) at the config's air
    density (SIM_Frame.cpp:579-584, SIM_Motor.cpp:217-218)."""
    rho_ratio = _air_density(ALTITUDE) / _air_density(REF_ALTITUDE)
    full = MASS * SITL_GRAVITY / (4.0 * HOVER_THROTTLE) * rho_ratio
    p, n_max = sitl_quad.parameters, sitl_quad.limits.rotor_speed_max
    assert p.c_T * n_max**2 == pytest.approx(full, rel=1e-6)


def test_hovers_within_the_rotor_range(sitl_quad: VehicleConfig) -> None:
    """Hover needs about 62 % of the top rotor speed, and the top speed lifts 1.8 m g."""
    p, limits = sitl_quad.parameters, sitl_quad.limits
    hover = rotor_speed_for_thrust(p.c_T, sitl_quad.mass * GRAVITY / sitl_quad.rotor_count)
    assert limits.rotor_speed_min < hover < limits.rotor_speed_max
    assert 0.3 < hover / limits.rotor_speed_max < 0.8
    lift = sitl_quad.rotor_count * p.c_T * limits.rotor_speed_max**2
    assert lift >= limits.thrust_max_ratio * sitl_quad.mass * GRAVITY


def _hover_command(sitl_quad: VehicleConfig) -> float:
    """SITL's hover command c (SITL's gravity): the root of the thrust fraction."""
    p, n_max = sitl_quad.parameters, sitl_quad.limits.rotor_speed_max
    fraction = MASS * SITL_GRAVITY / 4.0 / (p.c_T * n_max**2)
    e = PROP_EXPO
    return (-(1.0 - e) + math.sqrt((1.0 - e) ** 2 + 4.0 * e * fraction)) / (2.0 * e)


def test_moment_coefficient_matches_sitl_yaw_slope_at_hover(sitl_quad: VehicleConfig) -> None:
    """d(c_M n²)/dn = d(0.05 · diagonal_size · c · T)/dn at hover (SIM_Motor.cpp:71-72)."""
    p, n_max = sitl_quad.parameters, sitl_quad.limits.rotor_speed_max
    c = _hover_command(sitl_quad)
    step = 1e-6

    def n_of(cmd: float) -> float:
        return n_max * math.sqrt(_thrust_fraction(cmd))

    def sitl_yaw(cmd: float) -> float:
        return 0.05 * DIAGONAL_SIZE * cmd * p.c_T * n_of(cmd) ** 2

    slope = (sitl_yaw(c + step) - sitl_yaw(c - step)) / (n_of(c + step) - n_of(c - step))
    assert 2.0 * p.c_M * n_of(c) == pytest.approx(slope, rel=1e-5)


def test_drag_coefficient_matches_sitl_momentum_drag_at_hover(sitl_quad: VehicleConfig) -> None:
    """c_T n² c_D = mdrag_coef sqrt(ρ A_rotor) sqrt(T) at hover thrust (SIM_Motor.cpp:111-114)."""
    rho = _air_density(ALTITUDE)
    hover = MASS * SITL_GRAVITY / 4.0
    momentum = MOMENTUM_DRAG_COEF * math.sqrt(rho * DISC_AREA / 4.0) * math.sqrt(hover)
    assert sitl_quad.parameters.c_D * hover == pytest.approx(momentum, rel=1e-4)


def test_rotor_pairs_balance_yaw_in_hover(sitl_quad: VehicleConfig) -> None:
    """Two rotors spin each way, and diagonal rotors share a spin (a yaw-neutral X)."""
    eps = sitl_quad.rotor_directions
    assert eps.sum() == 0
    positions = sitl_quad.rotor_positions
    for i, j in itertools.combinations(range(4), 2):
        opposite = np.allclose(positions[i], -positions[j])
        assert (eps[i] == eps[j]) == opposite
