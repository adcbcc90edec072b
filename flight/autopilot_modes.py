"""Flight modes of the two autopilot families mavsysid talks to, as MAVLink encodes them.

ArduPilot Copter puts its mode number straight into HEARTBEAT.custom_mode. PX4 packs a
union {uint16 reserved, uint8 main_mode, uint8 sub_mode} into it (px4_custom_mode.h).
Both set MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in base_mode, and MAV_MODE_FLAG_SAFETY_ARMED
while armed.
"""

from __future__ import annotations

from enum import Enum

__all__ = [
    "ARDUCOPTER_MODES",
    "PX4_MODES",
    "Autopilot",
    "mode_name",
    "px4_custom_mode",
]

#: ArduPilot Copter mode numbers (ArduCopter/mode.h).
ARDUCOPTER_MODES: dict[str, int] = {
    "STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5,
    "RTL": 6, "CIRCLE": 7, "LAND": 9, "POSHOLD": 16, "BRAKE": 17,
}


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """PX4 custom_mode from main and sub mode (px4_custom_mode.h union layout).

    Parameters
    ----------
    main : int
        PX4 main mode.
    sub : int
        PX4 sub mode.
    """
    return (main << 16) | (sub << 24)


#: PX4 modes used here: main 1 MANUAL, 3 POSCTL, 4 AUTO (sub 2 TAKEOFF, 3 LOITER = Hold,
#: 6 LAND), 6 OFFBOARD.
PX4_MODES: dict[str, int] = {
    "MANUAL": px4_custom_mode(1),
    "POSCTL": px4_custom_mode(3),
    "TAKEOFF": px4_custom_mode(4, 2),
    "HOLD": px4_custom_mode(4, 3),
    "LAND": px4_custom_mode(4, 6),
    "OFFBOARD": px4_custom_mode(6),
}


class Autopilot(Enum):
    """Autopilot family, from HEARTBEAT.autopilot (MAV_AUTOPILOT_ARDUPILOTMEGA = 3,
    MAV_AUTOPILOT_PX4 = 12)."""

    ARDUPILOT = 3
    PX4 = 12

    @property
    def modes(self) -> dict[str, int]:
        """Mode name → custom_mode."""
        return ARDUCOPTER_MODES if self is Autopilot.ARDUPILOT else PX4_MODES

    @classmethod
    def from_heartbeat(cls, autopilot: int) -> Autopilot | None:
        """The family of a HEARTBEAT.autopilot value; None for others (e.g. a GCS).

        Parameters
        ----------
        autopilot : int
            HEARTBEAT.autopilot (MAV_AUTOPILOT).
        """
        try:
            return cls(autopilot)
        except ValueError:
            return None


def mode_name(autopilot: Autopilot, custom_mode: int) -> str:
    """Readable name of a custom_mode (``"mode 23"`` when unknown).

    Parameters
    ----------
    autopilot : Autopilot
        The family.
    custom_mode : int
        HEARTBEAT.custom_mode.
    """
    for name, value in autopilot.modes.items():
        if value == custom_mode:
            return name
    if autopilot is Autopilot.PX4:
        return f"mode main {(custom_mode >> 16) & 0xFF} sub {(custom_mode >> 24) & 0xFF}"
    return f"mode {custom_mode}"
