"""The end of a landing: touchdown seen, motors disarmed.

After LAND an autopilot disarms by itself once its land detector sees the touchdown
(ArduCopter at once in LAND; PX4 after COM_DISARM_LAND). `wait_disarmed` waits for that,
for as long as the vehicle still comes down, and helps where the autopilot does not:

1. Touchdown: EXTENDED_SYS_STATE reports ON_GROUND, or the vehicle rests (speed below
   `LandingLimits.rest_speed`) within `LandingLimits.ground_band` of its take-off height.
2. Still armed `LandingLimits.own_disarm` s later: a ground station's disarm, every few
   seconds, which the autopilot accepts only when it too believes it has landed.
3. Refused, and the vehicle has rested on the ground in LAND for `LandingLimits.rest_time`
   s: a forced disarm (MAV_CMD_COMPONENT_ARM_DISARM param2 21196), with a line saying why.
   ArduCopter in strong wind (8 m/s on SITL, measured) sits on the ground for minutes with
   its attitude controller fighting the wind, so its land detector never sees the motors at
   their lower limit: it neither disarms nor lets a ground station disarm, and without the
   forced disarm the vehicle stays armed, propellers turning, until someone walks up to it.
   The force is never used away from the take-off height or while the vehicle moves.

The wait gives up only after `LandingLimits.stall` s in which the vehicle came no lower
(or, on the ground, could not be disarmed), with one line saying so; someone else
changing the mode ends it at once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.vehicle_commands import (
    MAV_CMD_COMPONENT_ARM_DISARM,
    CommandRejected,
    VehicleCommands,
)

from mavsysid.errors import JobFailedError

__all__ = ["FORCE_DISARM", "LandingLimits", "wait_disarmed"]

#: MAV_CMD_COMPONENT_ARM_DISARM param2 that disarms whatever the autopilot's own checks say.
FORCE_DISARM = 21196
_ON_GROUND = 1  # MAV_LANDED_STATE_ON_GROUND


@dataclass(frozen=True)
class LandingLimits:
    """When a landing counts as done, and when mavsysid disarms (streamer seconds).

    Attributes
    ----------
    rest_speed : float
        At rest below this speed, m/s (every axis).
    ground_band : float
        On the ground within this of the take-off height, m.
    own_disarm : float
        On the ground this long and still armed: a ground station's disarm.
    rest_time : float
        At rest on the ground this long and the disarm refused: a forced one.
    retry : float
        Between disarm attempts.
    stall : float
        Give up after this long with neither descent nor the ground.
    """

    rest_speed: float = 0.1
    ground_band: float = 0.5
    own_disarm: float = 3.0
    rest_time: float = 10.0
    retry: float = 3.0
    stall: float = 60.0


class _Descent:
    """What the vehicle's telemetry says about the landing (a link listener)."""

    def __init__(self, home_up: float | None, limits: LandingLimits) -> None:
        self.home_up, self.limits = home_up, limits
        self.landed_state: int | None = None
        self.up: float | None = None
        self.lowest: float | None = None
        self.rest_since: float | None = None
        self.progress = 0.0

    def on_message(self, msg: Any, t: float) -> None:
        kind = msg.get_type()
        if kind == "EXTENDED_SYS_STATE":
            self.landed_state = msg.landed_state
        elif kind == "LOCAL_POSITION_NED":
            self.up = -float(msg.z)
            if self.lowest is None or self.up < self.lowest - 0.05:
                self.lowest, self.progress = self.up, t
            still = max(abs(msg.vx), abs(msg.vy), abs(msg.vz)) < self.limits.rest_speed
            self.rest_since = (self.rest_since or t) if still else None

    def near_ground(self) -> bool:
        return (self.home_up is not None and self.up is not None
                and abs(self.up - self.home_up) <= self.limits.ground_band)

    def resting(self, now: float) -> float:
        """Seconds at rest on the ground (0 when moving or away from it)."""
        if self.rest_since is None or not self.near_ground():
            return 0.0
        return now - self.rest_since

    def on_ground(self, now: float) -> bool:
        return self.landed_state == _ON_GROUND or self.resting(now) > 0.0

    def offset(self) -> str:
        """Height above the take-off point, for messages."""
        if self.up is None or self.home_up is None:
            return "an unknown height"
        return f"{self.up - self.home_up:+.2f} m"


def _disarm(commands: VehicleCommands, force: bool) -> str | None:
    """Send a disarm; None when accepted, else the autopilot's answer."""
    try:
        commands.command(MAV_CMD_COMPONENT_ARM_DISARM, (0, FORCE_DISARM if force else 0),
                         what="forced disarm" if force else "disarm", retry_rejected=False)
    except CommandRejected as error:
        return error.result_name
    except JobFailedError as error:
        return str(error)
    return None


def wait_disarmed(link: MavlinkLink, commands: VehicleCommands, say: Callable[[str], None],
                  home_up: float | None, limits: LandingLimits | None = None) -> bool:
    """After LAND: wait until the vehicle has landed and is disarmed (module docstring).

    Parameters
    ----------
    link : MavlinkLink
        The vehicle, in the LAND mode mavsysid set.
    commands : VehicleCommands
        For the disarm commands.
    say : callable
        Receives one-line reports.
    home_up : float or None
        The take-off height, m up in the vehicle's local frame (−LOCAL_POSITION_NED z);
        None: unknown, and a refused disarm is never forced.
    limits : LandingLimits, optional

    Returns
    -------
    bool
        True once disarmed; False when someone else changed the mode or the landing
        stalled (a line says which).
    """
    limits = limits or LandingLimits()
    descent = _Descent(home_up, limits)
    link.add_listener(descent.on_message)
    try:
        commands.set_message_interval("EXTENDED_SYS_STATE", 2.0)
        return _wait(link, commands, say, descent, limits)
    finally:
        link.remove_listener(descent.on_message)


def _wait(link: MavlinkLink, commands: VehicleCommands, say: Callable[[str], None],
          descent: _Descent, limits: LandingLimits) -> bool:
    clock, vehicle = link.clock, link.vehicle
    ours = vehicle.custom_mode
    descent.progress = clock.now()
    grounded: float | None = None
    next_try, refused = -1.0, None
    while vehicle.armed:
        now = clock.now()
        if vehicle.custom_mode != ours:
            say(f"the operator took over (mode {vehicle.mode}); not waiting for the landing")
            return False
        grounded = (grounded or now) if descent.on_ground(now) else None
        if grounded is not None and now - grounded >= limits.own_disarm and now >= next_try:
            next_try = now + limits.retry
            refused = _disarm(commands, force=False)
            if refused is not None and descent.resting(now) >= limits.rest_time:
                say(f"the autopilot refuses to disarm ({refused}): its land detector has not "
                    f"seen the touchdown, but the vehicle has rested {descent.resting(now):.0f} s"
                    f" at {descent.offset()} from its take-off height in LAND; forced disarm")
                _disarm(commands, force=True)
        since = descent.progress if grounded is None else grounded + limits.rest_time
        if now - since > limits.stall:
            state = ("on the ground, the disarm refused" + (f" ({refused})" if refused else "")
                     if grounded is not None else "no longer coming lower")
            say(f"warning: still armed, {state} ({descent.offset()} from its take-off "
                "height); disarm it from the transmitter or ground station")
            return False
        link.poll(0.1)
    say("landed and disarmed")
    return True
