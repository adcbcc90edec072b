"""Checks of an assembled vehicle configuration that no single TOML key shows.

`mavsysid.vehicle.config_schema.validate_document` checks the document key by key;
`check_vehicle` then checks the assembled `VehicleConfig`: inertia consistency (a
warning only: a prior is a guess), a c_M that is really a ratio, rotor allocation rank,
lift and the order of limits. Problems
raise the one-line `ConfigError` of `mavsysid.vehicle.config_schema`.
"""

from __future__ import annotations

import warnings

import numpy as np
from mavsysid.vehicle.allocation import allocation_matrix
from mavsysid.vehicle.config_schema import describe_value, raise_config_error
from mavsysid.vehicle.config_types import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import rotor_thrust

__all__ = [
    "INERTIA_TRIANGLE_SLACK", "InertiaWarning", "check_vehicle", "triangle_violation",
]

#: Relative slack of the rigid-body triangle inequality j_a + j_b ≥ j_c, for a config's
#: inertia (beyond it: a warning) and for an estimated one (beyond it: refused). The RotorS
#: Firefly inertia (the reference vehicle of docs/architecture.md) has j_z 21 % above
#: j_x + j_y, which no rigid body can have; 25 % keeps that reference unflagged while still
#: catching decimal-point slips and swapped units (factors ≥ 10).
INERTIA_TRIANGLE_SLACK = 0.25
# c_M/c_T is the rotor's torque-to-thrust lever, a few cm on any real propeller;
# RotorS's ratio (≈ 0.016 m for the Firefly) passed as c_M gives a value ≥ 1000 m.
_MAX_MOMENT_ARM = 0.1
# Relative singular-value threshold below which an allocation direction is missing.
_RANK_RTOL = 1e-9


class InertiaWarning(UserWarning):
    """A config inertia that breaks the rigid-body triangle inequality beyond the slack.

    A prior is a guess (the paper's own Firefly values break the inequality), so it is
    reported, not refused; an *estimate* that breaks it is refused
    (`mavsysid.estimation.checks`).
    """


def triangle_violation(
    J: np.ndarray | tuple[float, float, float], slack: float = INERTIA_TRIANGLE_SLACK,
) -> tuple[int, int, int] | None:
    """The first principal moment that exceeds the sum of the other two by more than ``slack``.

    Parameters
    ----------
    J : array_like, shape (3,)
        Principal moments j_x, j_y, j_z, kg·m².
    slack : float
        Relative tolerance: j_c > (1 + slack)(j_a + j_b) is a violation.

    Returns
    -------
    tuple of 3 int or None
        Indices (c, a, b) of the violation, None when the inequality holds.
    """
    j = np.asarray(J, dtype=float)
    for c in range(3):
        a, b = (c + 1) % 3, (c + 2) % 3
        if j[c] > (1.0 + slack) * (j[a] + j[b]):
            return c, a, b
    return None


def _rank_ok(rows: np.ndarray) -> bool:
    """Whether the rows are linearly independent, each row scaled to unit max first."""
    scale = np.max(np.abs(rows), axis=1, keepdims=True)
    if np.any(scale == 0.0):
        return False
    # Rows differ by orders of magnitude (c_T ≈ 1e-5 vs c_M ≈ 1e-7): normalise so
    # the rank test measures geometry, not units.
    s = np.linalg.svd(rows / scale, compute_uv=False)
    return bool(s[-1] > _RANK_RTOL * s[0])


def _check_allocation(file: str, config: VehicleConfig) -> None:
    """Check the 4×k allocation [c_T; c_T y; -c_T x; -ε c_M] has rank 4, naming the gap."""
    thrust, roll, pitch, yaw = allocation_matrix(config)
    eps = config.rotor_directions
    directions = "(" + ", ".join(f"{int(e):+d}" for e in eps) + ")"
    if not _rank_ok(np.vstack([thrust, yaw])):
        raise_config_error(
            file, "[[rotors]].direction",
            "rotors spinning both ways (+1 and -1) so that yaw torque can be produced "
            "independently of thrust", f"all directions {int(eps[0]):+d}")
    if not _rank_ok(np.vstack([thrust, roll, pitch])):
        raise_config_error(
            file, "[[rotors]].position",
            "rotor positions spanning the x-y plane so that roll and pitch torque can be "
            "produced", "all rotors on one line in the x-y plane")
    if not _rank_ok(np.vstack([thrust, roll, pitch, yaw])):
        raise_config_error(
            file, "[[rotors]].direction",
            "directions that let yaw torque be produced independently of thrust, roll and "
            "pitch torque", f"directions {directions}, which follow the rotor layout")


def check_vehicle(file: str, config: VehicleConfig) -> None:
    """Check the properties of an assembled configuration that no single key shows.

    Parameters
    ----------
    file : str
        How the file is named in error messages.
    config : VehicleConfig
        The configuration built from a document that passed `validate_document`.

    Raises
    ------
    ConfigError
        A c_M that is RotorS's ratio c_M/c_T, rotors that cannot
        produce independent thrust, roll, pitch and yaw torque, rotors that cannot lift
        the vehicle, limits in the wrong order, or a motor curve out of range (pwm_min ≥
        pwm_max, thrust_expo > 1).

    Warns
    -----
    InertiaWarning
        An inertia breaking the triangle inequality by more than `INERTIA_TRIANGLE_SLACK`.
    """
    params = config.parameters
    j = params.J
    violation = triangle_violation(j)
    if violation is not None:
        c, a, b = violation
        names = ("j_x", "j_y", "j_z")
        # One line, like the errors; stacklevel points at the caller of load_vehicle.
        warnings.warn(
            f"{file}: [parameters].J: {describe_value(list(j))} breaks the rigid-body "
            f"triangle inequality ({names[a]} + {names[b]} = {j[a] + j[b]:.6g} < "
            f"{names[c]} = {j[c]:.6g}, more than {INERTIA_TRIANGLE_SLACK:.0%} over); used as "
            "the prior anyway, an estimate must satisfy it", InertiaWarning, stacklevel=4)
    arm = params.c_M / params.c_T
    if arm >= _MAX_MOMENT_ARM:
        raise_config_error(
            file, "[parameters].c_M",
            "the absolute moment coefficient in N·m/(rad/s)² (c_M/c_T is a few cm at most)",
            f"{params.c_M!r}, which looks like the ratio c_M/c_T; the absolute coefficient "
            f"is ratio × c_T = {params.c_M!r} × {params.c_T!r} = {params.c_M * params.c_T:.6g}")
    _check_allocation(file, config)
    limits = config.limits
    k = config.rotor_count
    lift = k * rotor_thrust(params.c_T, limits.rotor_speed_max)
    weight = config.mass * GRAVITY
    if lift < weight:
        raise_config_error(file, "[limits].rotor_speed_max",
                           f"a speed at which the {k} rotors lift the vehicle ({k} × c_T × "
                           f"rotor_speed_max² ≥ m g = {weight:.6g} N)",
                           f"{limits.rotor_speed_max!r} rad/s giving {lift:.6g} N")
    if limits.rotor_speed_min >= limits.rotor_speed_max:
        raise_config_error(file, "[limits].rotor_speed_min",
                           f"a speed in [0, rotor_speed_max = {limits.rotor_speed_max!r}) rad/s",
                           repr(limits.rotor_speed_min))
    motor = config.motor
    if motor.pwm_min >= motor.pwm_max:
        raise_config_error(file, "[motor].pwm_min", f"a PWM below pwm_max = {motor.pwm_max!r} µs",
                           repr(motor.pwm_min))
    if motor.thrust_expo > 1.0:
        raise_config_error(file, "[motor].thrust_expo", "a number between 0 and 1",
                           repr(motor.thrust_expo))
    if limits.thrust_min_ratio >= limits.thrust_max_ratio:
        raise_config_error(file, "[limits].thrust_min_ratio",
                           f"a ratio below thrust_max_ratio = {limits.thrust_max_ratio!r}",
                           repr(limits.thrust_min_ratio))
