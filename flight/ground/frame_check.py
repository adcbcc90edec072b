"""The autopilot's frame against the vehicle file's, before arming.

The vehicle file says which rotor each motor output drives (``[autopilot] frame``, or
output i is rotor i without it); the autopilot's own parameters say how it mixes:

- **ArduPilot**: FRAME_CLASS and FRAME_TYPE (`mavsysid.vehicle.motor_order.ardupilot_frame_name`).
- **PX4**: the rotor geometry of its control allocation (CA_ROTOR_COUNT, CA_ROTORn_PX,
  CA_ROTORn_PY and the sign of CA_ROTORn_KM for the spin, PX4 ≥ 1.14), else the airframe
  group of SYS_AUTOSTART (`mavsysid.vehicle.motor_order.px4_airframe_frame`).

A file that names a frame must name the autopilot's (its motor numbering is what the logs
hold); a file without one must at least have its rotors where the autopilot's frame has
them (a "+" autopilot flown with an X file turns its rotors 45° from where the file says).
A mismatch refuses the flight in one line: estimated with the wrong file, the flight gives a
confident wrong θ, or rotors that "never spun". An autopilot that does not report its frame
draws a warning.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.preflight import PreflightReport
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.motor_order import (
    ANGLE_TOLERANCE_DEG,
    MotorOrderError,
    ardupilot_frame_name,
    describe_angle,
    layout_matches,
    output_order,
    px4_airframe_frame,
)

__all__ = ["ARDUPILOT_FRAME_PARAMETERS", "PX4_ROTOR_LIMIT", "check_frame",
           "frame_parameter_names", "px4_rotor_parameter_names"]

#: ArduPilot's frame parameters.
ARDUPILOT_FRAME_PARAMETERS = ("FRAME_CLASS", "FRAME_TYPE")
#: Most rotors PX4's control allocation describes (CA_ROTOR0 … CA_ROTOR11).
PX4_ROTOR_LIMIT = 12


def frame_parameter_names(autopilot: Autopilot) -> tuple[str, ...]:
    """The parameters read first: ArduPilot's frame, PX4's rotor count and airframe.

    Parameters
    ----------
    autopilot : Autopilot
        The family the heartbeat reported.
    """
    if autopilot is Autopilot.ARDUPILOT:
        return ARDUPILOT_FRAME_PARAMETERS
    return ("CA_ROTOR_COUNT", "SYS_AUTOSTART")


def px4_rotor_parameter_names(count: int) -> tuple[str, ...]:
    """PX4's geometry parameters of ``count`` rotors (position in body FRD, moment sign).

    Parameters
    ----------
    count : int
        CA_ROTOR_COUNT (at most `PX4_ROTOR_LIMIT` are read).
    """
    return tuple(f"CA_ROTOR{i}_{key}" for i in range(min(count, PX4_ROTOR_LIMIT))
                 for key in ("PX", "PY", "KM"))


def _vehicle_words(config: VehicleConfig) -> str:
    frame = config.autopilot_frame
    return (f"the vehicle file {config.name} says {frame}" if frame is not None else
            f"the vehicle file {config.name} names no [autopilot] frame")


def _compare_named(config: VehicleConfig, flown: str, flown_words: str) -> PreflightReport:
    """The autopilot flies the known frame ``flown``: the file must name it, or (naming
    none) have its rotors where ``flown`` has them."""
    named = config.autopilot_frame
    if named == flown:
        return PreflightReport()
    if named is None:
        if layout_matches(config.rotor_positions, flown):
            return PreflightReport()
        return PreflightReport((f"the autopilot flies {flown} ({flown_words}) but the rotors "
                                f"of {config.name} are not where that frame has them; "
                                "check FRAME_CLASS/FRAME_TYPE or the vehicle file",))
    return PreflightReport((f"the autopilot flies {flown} ({flown_words}) but "
                            f"{_vehicle_words(config)}: the motor outputs would be read as "
                            "other rotors; fix the autopilot's frame or the vehicle file",))


def _check_ardupilot(config: VehicleConfig, values: Mapping[str, float]) -> PreflightReport:
    if not all(n in values for n in ARDUPILOT_FRAME_PARAMETERS):
        return PreflightReport(warnings=("the autopilot did not report FRAME_CLASS and "
                                         "FRAME_TYPE: its frame is not checked against "
                                         f"{config.name}",))
    flown, words = ardupilot_frame_name(int(values["FRAME_CLASS"]), int(values["FRAME_TYPE"]))
    if flown is None:
        return PreflightReport((f"the autopilot flies {words}, a frame mavsysid has no motor "
                                f"table for, but {_vehicle_words(config)}",))
    return _compare_named(config, flown, words)


def _px4_geometry(values: Mapping[str, float], count: int) -> tuple[np.ndarray, np.ndarray]:
    """PX4's rotor positions (body FLU, unit scale) and spins (+1 CCW) in output order."""
    positions = np.array([[values[f"CA_ROTOR{i}_PX"], -values[f"CA_ROTOR{i}_PY"], 0.0]
                          for i in range(count)])
    spins = np.array([1 if values[f"CA_ROTOR{i}_KM"] > 0 else -1 for i in range(count)])
    return positions, spins


def _expected_outputs(config: VehicleConfig) -> list[tuple[float, int]] | None:
    """(angle clockwise from the nose, spin) per motor output as the file has them."""
    try:
        order = output_order(config.rotor_positions, config.rotor_directions,
                             config.autopilot_frame)
    except MotorOrderError:
        return None  # the config checks have refused such a file already
    p = config.rotor_positions
    return [(math.degrees(math.atan2(-p[j, 1], p[j, 0])), int(config.rotor_directions[j]))
            for j in order]


def _check_px4_geometry(config: VehicleConfig, values: Mapping[str, float],
                        count: int) -> PreflightReport:
    if count != config.rotor_count:
        return PreflightReport((f"the autopilot's control allocation has {count} rotors "
                                f"(CA_ROTOR_COUNT) but {config.name} has {config.rotor_count}",))
    positions, spins = _px4_geometry(values, count)
    expected = _expected_outputs(config)
    if expected is None:
        return PreflightReport()
    angles = np.degrees(np.arctan2(-positions[:, 1], positions[:, 0]))
    for i, ((angle, spin), flown, flown_spin) in enumerate(
            zip(expected, angles, spins, strict=True)):
        gap = abs((angle - flown + 180.0) % 360.0 - 180.0)
        if gap > ANGLE_TOLERANCE_DEG or spin != flown_spin:
            turn = "counter-clockwise" if flown_spin > 0 else "clockwise"
            return PreflightReport((
                f"motor {i + 1} of the autopilot (CA_ROTOR{i}) is at the "
                f"{describe_angle(round(float(flown), 1))}, spinning {turn}, but "
                f"{_vehicle_words(config)}, which puts motor {i + 1} at the "
                f"{describe_angle(round(angle, 1))}, "
                f"{'counter-clockwise' if spin > 0 else 'clockwise'}",))
    return PreflightReport()


def _check_px4(config: VehicleConfig, values: Mapping[str, float]) -> PreflightReport:
    count = int(values.get("CA_ROTOR_COUNT", 0))
    if count > 0 and all(n in values for n in px4_rotor_parameter_names(count)):
        return _check_px4_geometry(config, values, count)
    if "SYS_AUTOSTART" not in values:
        return PreflightReport(warnings=("the autopilot reported neither its control "
                                         "allocation (CA_ROTOR*) nor SYS_AUTOSTART: its frame "
                                         f"is not checked against {config.name}",))
    airframe = int(values["SYS_AUTOSTART"])
    flown = px4_airframe_frame(airframe)
    if flown is None:
        return PreflightReport(warnings=(f"the autopilot's airframe SYS_AUTOSTART {airframe} "
                                         "is not a plain quad, hexa or octo: its frame is "
                                         f"not checked against {config.name}",))
    return _compare_named(config, flown, f"SYS_AUTOSTART {airframe}")


def check_frame(config: VehicleConfig, autopilot: Autopilot,
                values: Mapping[str, float]) -> PreflightReport:
    """Refuse a vehicle file whose frame is not the autopilot's (see the module docstring).

    Parameters
    ----------
    config : VehicleConfig
        The vehicle file flown with: its rotors and ``[autopilot] frame``.
    autopilot : Autopilot
        The family the heartbeat reported.
    values : mapping
        The autopilot's parameters read (`frame_parameter_names`, and for PX4
        `px4_rotor_parameter_names`); absent ones were not reported.

    Returns
    -------
    PreflightReport
        One refusal naming both frames, or a warning when the autopilot did not say.
    """
    named = config.autopilot_frame
    if named is not None and not named.startswith(autopilot.name.lower() + ":"):
        return PreflightReport((f"the vehicle is {autopilot.name.lower()} but "
                                f"{_vehicle_words(config)}, another autopilot's motor "
                                "numbering",))
    if autopilot is Autopilot.ARDUPILOT:
        return _check_ardupilot(config, values)
    return _check_px4(config, values)
