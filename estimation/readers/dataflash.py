"""ArduPilot DataFlash logs (``.bin``), read with pymavlink's DFReader.

Pose: the best source present (`mavsysid.estimation.readers.dataflash_pose`): ``VISP``
(motion capture), else the autopilot's EKF3/EKF2 estimate, else ``POS`` with ``ATT``.

Rotor speeds (`mavsysid.estimation.readers.dataflash_motors`): ``ESC`` (or, older,
``ESC1``..``ESC8``) RPM by instance, else ``RCOU`` PWM (``C1..``, ``Ch1..`` or ``Chan1..``)
through the vehicle's `[motor]` curve (with a warning). ESC instance i and output channel
i + 1 are motor output i + 1, put into the config's rotor order by
`mavsysid.estimation.readers.motor_outputs`. Times are TimeUS (µs since boot) or, in logs
before ArduCopter 3.3, TimeMS → s.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

from mavsysid.estimation.readers.dataflash_messages import Messages
from mavsysid.estimation.readers.dataflash_motors import MOTOR_TYPES, esc_rotors, rcou_channels
from mavsysid.estimation.readers.dataflash_pose import POSE_HINT, POSE_TYPES, dataflash_pose
from mavsysid.estimation.readers.guard import import_parser, parsing
from mavsysid.estimation.readers.motor_curve import describe_curve, rotor_speed_from_pwm
from mavsysid.estimation.readers.motor_outputs import motor_output_count, rotors_in_config_order
from mavsysid.estimation.readers.streams import LogStreams, Series
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import LogFormatError

__all__ = ["read_dataflash"]

_TYPES = [*POSE_TYPES, *MOTOR_TYPES]


def _collect(path: Path) -> Messages:
    """The messages of the types used here, by type."""
    DFReader = import_parser("pymavlink.DFReader", path)
    found: Messages = defaultdict(list)
    with parsing(path, "an ArduPilot DataFlash log"):
        log = DFReader.DFReader_binary(str(path))
        try:
            while (m := log.recv_match(type=_TYPES)) is not None:
                found[m.get_type()].append(m)
        finally:
            log.close()
    return found


def _rcou_rotors(rows: list[Any], vehicle: VehicleConfig) -> Series | None:
    """RCOU channels 1..k PWM through the motor curve; None if no channel ever outputs."""
    t, pwm = rcou_channels(rows)
    count = motor_output_count(pwm)
    if count == 0:
        return None
    return Series(t, rotor_speed_from_pwm(pwm[:, :count], vehicle), "RCOU PWM")


def read_dataflash(path: Path, vehicle: VehicleConfig) -> LogStreams:
    """Read the pose and rotor speeds of an ArduPilot DataFlash log.

    Parameters
    ----------
    path : Path
        The ``.bin`` file.
    vehicle : VehicleConfig
        The vehicle: its rotor count and motor curve (for RCOU outputs).

    Returns
    -------
    LogStreams
        In ENU/FLU and rad/s, on the autopilot's clock (s since boot).

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    found = _collect(path)
    with parsing(path, "an ArduPilot DataFlash log with the usual message fields"):
        pose, pose_source, notes = dataflash_pose(path, found)
        rcou = _rcou_rotors(found["RCOU"], vehicle) if found.get("RCOU") else None
        escs = esc_rotors(path, found)
        if escs is not None:
            rotors = escs
        elif rcou is not None:
            rotors = (rcou,)
            notes.append(f"{path}: no ESC rpm; rotor speeds are RCOU motor outputs through the "
                         f"motor curve {describe_curve(vehicle, pwm=True)}: commanded, not "
                         "measured, and only as right as the [motor] keys of the vehicle config")
        else:
            raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no ESC "
                                 "RPM, no RCOU)")
    rotors, ordered = rotors_in_config_order(str(path), rotors, vehicle)
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source, rotors=rotors,
                      warnings=(*notes, *ordered), pose_hint=POSE_HINT)
