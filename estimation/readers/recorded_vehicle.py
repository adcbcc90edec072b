"""The vehicle a flight was flown as, from the ``meta.json`` beside its log, against ``--vehicle``.

`mavsysid stream`, `sim` and `experiment` record the whole vehicle file they flew with
(``vehicle.config_toml``). Mass and rotor geometry are taken as known by the estimate (a
wrong mass scales c_T, c_M and J together, and nothing in pose and rotor speeds shows it),
and a log without rotor speeds reads its motor outputs through the file's ``[motor]``
curve. So a flight read with another vehicle's file than the one it was flown with gets a
confident wrong θ: that is refused in one line. The same vehicle name with other values
(the file edited since, say after weighing the vehicle) is a warning, not a refusal.
"""

from __future__ import annotations

import math
from pathlib import Path

from mavsysid.formats.flight_dir import read_meta
from mavsysid.vehicle.config import VehicleConfig, vehicle_from_toml

from mavsysid.errors import ConfigError, InputError, LogFormatError

__all__ = ["MASS_TOLERANCE", "ROTOR_TOLERANCE", "check_recorded_vehicle", "recorded_vehicle",
           "vehicle_differences"]

#: Masses differing by more than this share are different vehicles.
MASS_TOLERANCE = 0.005
#: Rotor positions differing by more than this, m, are different geometries.
ROTOR_TOLERANCE = 1e-3


def recorded_vehicle(log: Path) -> VehicleConfig | None:
    """The vehicle recorded in the ``meta.json`` beside ``log``; None without one.

    Parameters
    ----------
    log : Path
        The flight log.

    Raises
    ------
    LogFormatError
        A ``meta.json`` whose recorded vehicle is not a valid vehicle file; one line.
    """
    meta_path = log.parent / "meta.json"
    if not meta_path.is_file():
        return None
    vehicle = read_meta(meta_path).get("vehicle")
    text = vehicle.get("config_toml") if isinstance(vehicle, dict) else None
    if not isinstance(text, str):
        return None
    try:
        return vehicle_from_toml(text, f"{meta_path} vehicle.config_toml")
    except ConfigError as error:
        raise LogFormatError(str(error)) from None


def vehicle_differences(recorded: VehicleConfig, given: VehicleConfig) -> list[str]:
    """What the estimate takes as known that differs between two vehicle files, in words.

    Parameters
    ----------
    recorded, given : VehicleConfig
        The vehicle the flight was flown as, and the one given to read it with.
    """
    out = []
    if not math.isclose(recorded.mass, given.mass, rel_tol=MASS_TOLERANCE):
        out.append(f"mass {recorded.mass:g} kg (not {given.mass:g} kg)")
    if recorded.rotor_count != given.rotor_count:
        out.append(f"{recorded.rotor_count} rotors (not {given.rotor_count})")
    else:
        moved = [i + 1 for i, (a, b) in enumerate(zip(recorded.rotors, given.rotors,
                                                      strict=True))
                 if math.dist(a.position, b.position) > ROTOR_TOLERANCE
                 or a.direction != b.direction]
        if moved:
            out.append(f"rotor geometry (rotor {', '.join(map(str, moved))})")
    motor_keys = ("pwm_min", "pwm_max", "thrust_expo")
    if (any(getattr(recorded.motor, k) != getattr(given.motor, k) for k in motor_keys)
            or recorded.limits.rotor_speed_max != given.limits.rotor_speed_max):
        out.append("motor curve ([motor] PWM range and expo, top rotor speed)")
    if recorded.autopilot_frame != given.autopilot_frame:
        out.append(f"autopilot frame {recorded.autopilot_frame or 'none'} "
                   f"(not {given.autopilot_frame or 'none'})")
    return out


def check_recorded_vehicle(log: Path, given: VehicleConfig) -> str | None:
    """Refuse a flight read with another vehicle's file than the one it was flown as.

    Parameters
    ----------
    log : Path
        The flight log; a ``meta.json`` beside it names the vehicle it was flown as.
    given : VehicleConfig
        The vehicle file the estimate was asked to use (``--vehicle``).

    Returns
    -------
    str or None
        A warning when the recorded vehicle has the given one's name but other values.

    Raises
    ------
    InputError
        The flight was flown as another vehicle whose mass, rotor geometry, motor curve or
        autopilot frame differs; one line naming both.
    """
    recorded = recorded_vehicle(log)
    if recorded is None:
        return None
    differences = vehicle_differences(recorded, given)
    if not differences:
        return None
    what = "; ".join(differences)
    if recorded.name == given.name:
        return (f"{log}: the vehicle file {given.name} differs from the one the flight was "
                f"flown with (meta.json: {what}); the estimate takes the file given")
    raise InputError(
        f"{log}: flown as vehicle {recorded.name} (meta.json), whose {what} differ from "
        f"--vehicle {given.name}: estimate with the vehicle the flight was flown with "
        f"(--vehicle {recorded.name} or its file)")
