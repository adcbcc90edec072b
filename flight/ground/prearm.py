"""Pre-arm health: wait for it, and say why the autopilot refuses to arm.

A freshly booted autopilot refuses to arm until its pre-arm checks pass (ArduCopter
SITL: ~25 s after boot, while the EKF converges and the GPS settles). It says so in two
ways, both watched here:

- SYS_STATUS: every sensor present and enabled is healthy, including the pseudo-sensor
  MAV_SYS_STATUS_PREARM_CHECK, whose health bit ArduPilot clears while a pre-arm check
  fails;
- STATUSTEXT: ArduPilot's ``"PreArm: …"`` lines (PX4: ``"Preflight Fail: …"``,
  ``"Arming denied…"``), the human reason, repeated every ~30 s while failing and
  again on each refused arm.

`PrearmMonitor.wait_ready` waits (with a timeout) until SYS_STATUS is healthy; the last
pre-arm text goes into the one-line message of a refused arm or a time-out.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from mavsysid.flight.ground.mavlink_link import MavlinkLink

from mavsysid.errors import JobFailedError

__all__ = ["PREARM_PREFIXES", "PrearmMonitor"]

#: STATUSTEXT starts that give an autopilot's reason for refusing to arm.
PREARM_PREFIXES = ("PreArm:", "Arm:", "Preflight Fail", "Arming denied")


class PrearmMonitor:
    """Watches SYS_STATUS and pre-arm STATUSTEXTs (add `on_message` as a link listener).

    Attributes
    ----------
    sys_status : message or None
        The last SYS_STATUS.
    last_text : str or None
        The last pre-arm STATUSTEXT.
    """

    def __init__(self, link: MavlinkLink) -> None:
        self.link = link
        self.sys_status: Any = None
        self.last_text: str | None = None

    def on_message(self, msg: Any, _t: float) -> None:
        """Note SYS_STATUS and pre-arm texts (a link listener)."""
        kind = msg.get_type()
        if kind == "SYS_STATUS":
            self.sys_status = msg
        elif kind == "STATUSTEXT":
            text = str(msg.text).rstrip("\x00").strip()
            if text.startswith(PREARM_PREFIXES):
                self.last_text = text

    def unhealthy(self) -> list[str]:
        """Names of the present, enabled sensors the last SYS_STATUS calls unhealthy."""
        s = self.sys_status
        if s is None:
            return []
        bad = (s.onboard_control_sensors_enabled & s.onboard_control_sensors_present
               & ~s.onboard_control_sensors_health)
        names = self.link.mavlink.enums["MAV_SYS_STATUS_SENSOR"]
        return [names[b].name.removeprefix("MAV_SYS_STATUS_").removeprefix("SENSOR_")
                if b in names else f"bit {b}" for b in (1 << i for i in range(32)) if bad & b]

    def reason(self) -> str:
        """The autopilot's own words (last pre-arm text), or the unhealthy sensors."""
        if self.last_text is not None:
            return self.last_text
        bad = self.unhealthy()
        return f"unhealthy: {', '.join(bad)}" if bad else "no reason given"

    def wait_ready(self, timeout: float, say: Callable[[str], None]) -> None:
        """Wait up to ``timeout`` streamer s for a healthy SYS_STATUS.

        Returns at once without a SYS_STATUS (the health check then warns). Says what
        it waits for every 5 s.

        Raises
        ------
        JobFailedError
            Still unhealthy after ``timeout``: names the sensors and the last pre-arm
            text.
        """
        clock = self.link.clock
        start = clock.now()
        next_note = start
        while self.sys_status is not None and (bad := self.unhealthy()):
            now = clock.now()
            if now - start > timeout:
                text = f"; the autopilot says \"{self.last_text}\"" if self.last_text else ""
                raise JobFailedError(f"flight refused: pre-arm checks still failing after "
                                     f"{timeout:g} s (unhealthy: {', '.join(bad)}){text}")
            if now >= next_note:
                text = f": {self.last_text}" if self.last_text else ""
                say(f"waiting for the pre-arm checks (unhealthy: {', '.join(bad)}){text} "
                    f"({now - start:.0f} s of {timeout:g} s)")
                next_note += 5.0
            self.link.poll(0.1)
