"""What the link knows of its vehicle, and when it counts the vehicle as lost.

`VehicleState` holds the vehicle's last HEARTBEAT (family, mode, armed) and the streamer
times of its last heartbeat and of its last message of any kind. `link_loss_problem`
decides that the link is lost, on two thresholds:

- **heartbeat loss**: no HEARTBEAT for ``heartbeat_loss`` s (``--heartbeat-loss``,
  default 3 s). Heartbeats come at 1 Hz, so this alone cannot see a loss in under ~2 s.
- **silence**: no message at all from the vehicle for ``silence`` s (``--link-loss``,
  default 1 s), watched only once the telemetry the flight asked for streams (tens of
  messages a second, so a second of silence is a dead link, not a gap). The limit is
  never below `MIN_SILENCE_WALL` s of wall time, so that a sped-up simulator on a loaded
  machine is not declared lost for a scheduling hiccup.

The check runs before every setpoint the link fires, so no setpoint leaves after the
loss is seen.
"""

from __future__ import annotations

from dataclasses import dataclass

from mavsysid.flight.autopilot_modes import Autopilot, mode_name

from mavsysid.errors import JobFailedError

__all__ = ["MIN_SILENCE_WALL", "HeartbeatLost", "LinkClosed", "VehicleState",
           "link_loss_problem"]

_ARMED_FLAG = 128  # MAV_MODE_FLAG_SAFETY_ARMED
#: The silence limit is never below this many wall seconds (scheduling hiccups).
MIN_SILENCE_WALL = 0.25


class HeartbeatLost(JobFailedError):
    """The vehicle went silent (no heartbeat, or no message at all) beyond its limit."""


class LinkClosed(HeartbeatLost):
    """The other end closed the TCP link (pymavlink would print "EOF" on every read), or the
    serial device failed."""


@dataclass
class VehicleState:
    """What the vehicle's last HEARTBEAT said, and when (streamer time, s).

    ``last_message`` is the receipt time of the vehicle's last message of any kind.
    """

    system: int = 0
    component: int = 0
    autopilot: Autopilot | None = None
    autopilot_id: int = 0
    mav_type: int = 0
    base_mode: int = 0
    custom_mode: int = 0
    system_status: int = 0
    last_heartbeat: float | None = None
    heartbeats: int = 0
    last_message: float | None = None

    @property
    def armed(self) -> bool:
        """Whether the motors are armed (MAV_MODE_FLAG_SAFETY_ARMED)."""
        return bool(self.base_mode & _ARMED_FLAG)

    @property
    def mode(self) -> str:
        """The flight mode's name (``"mode N"`` when unknown)."""
        if self.autopilot is None:
            return f"mode {self.custom_mode}"
        return mode_name(self.autopilot, self.custom_mode)


def link_loss_problem(vehicle: VehicleState, now: float, heartbeat_loss: float,
                      silence: float | None) -> str | None:
    """Why the vehicle counts as lost at streamer time ``now`` (s), or None.

    Parameters
    ----------
    vehicle : VehicleState
    now : float
        Streamer time, s.
    heartbeat_loss : float
        Longest gap between heartbeats, s.
    silence : float or None
        Longest gap between any two messages, s; None: not watched (yet).
    """
    last = vehicle.last_heartbeat
    if last is not None and now - last > heartbeat_loss:
        return (f"vehicle heartbeat lost: nothing for {now - last:.1f} s (limit "
                f"{heartbeat_loss:g} s)")
    heard = vehicle.last_message
    if silence is not None and heard is not None and now - heard > silence:
        return (f"vehicle heartbeat lost: no message at all from the vehicle for "
                f"{now - heard:.2f} s (link-loss limit {silence:g} s)")
    return None
