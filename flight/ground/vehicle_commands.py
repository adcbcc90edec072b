"""Commands to an ArduPilot or PX4 vehicle: COMMAND_LONG with its ACK, modes, arming.

Real autopilots answer every COMMAND_LONG with a COMMAND_ACK, but a packet can be lost
and a command can be refused for now (TEMPORARILY_REJECTED: a mode that needs a position
while the EKF is still converging, say; an arm refused FAILED by a pre-arm check that is
not ready yet). `VehicleCommands.command` resends a command that
got no answer (confirmation counting up, as MAVLink asks) and retries one rejected for
now, a few times each, and reports any other refusal with the MAV_RESULT name. Mode
changes and arming also wait for the HEARTBEAT showing them.

Mode encoding: ArduPilot takes MAV_CMD_DO_SET_MODE with param1 = custom mode enabled and
param2 = the Copter mode number; PX4 takes param2 = main mode and param3 = sub mode (its
custom_mode union). All waits go through `MavlinkLink.poll`, so a setpoint stream set as
the link's ticker keeps flowing meanwhile (PX4 needs that to enter OFFBOARD).
"""

from __future__ import annotations

import contextlib
from collections import deque
from collections.abc import Callable
from typing import Any

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.mavlink_link import MavlinkLink

from mavsysid.errors import JobFailedError

__all__ = ["CommandRejected", "VehicleCommands"]

MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
_ACCEPTED, _TEMPORARILY_REJECTED, _FAILED, _IN_PROGRESS = 0, 1, 4, 5
_CUSTOM_MODE_ENABLED = 1
#: ArduPilot EKF_STATUS_REPORT flags a usable local position needs: attitude, horizontal
#: and vertical velocity, relative and absolute horizontal position, vertical position.
EKF_POSITION_FLAGS = 1 | 2 | 4 | 8 | 16 | 32
_EKF_CONST_POS_MODE = 128
_EKF_FLAG_NAMES = {1: "ATTITUDE", 2: "VELOCITY_HORIZ", 4: "VELOCITY_VERT", 8: "POS_HORIZ_REL",
                   16: "POS_HORIZ_ABS", 32: "POS_VERT_ABS"}


class CommandRejected(JobFailedError):
    """The vehicle refused a command; ``result_name`` is the MAV_RESULT name."""

    def __init__(self, message: str, command: int, result: int, result_name: str) -> None:
        super().__init__(message)
        self.command, self.result, self.result_name = command, result, result_name


class VehicleCommands:
    """Commands to the vehicle of a `MavlinkLink` (see the module docstring).

    Parameters
    ----------
    link : MavlinkLink
        Connected, with the vehicle's heartbeat seen.
    say : callable, optional
        Receives progress lines (retries, waiting for a position).
    ack_timeout : float
        How long to wait for an ACK before resending, streamer s (never below 0.3 s of
        wall time, so that a sped-up clock does not outrun a loaded machine).
    attempts : int
        Sends of a command that gets no answer.
    rejected_retries : int
        Retries of a command TEMPORARILY_REJECTED, ``retry_delay`` apart (streamer s).
    """

    def __init__(self, link: MavlinkLink, say: Callable[[str], None] | None = None,
                 ack_timeout: float = 1.5, attempts: int = 3, rejected_retries: int = 5,
                 retry_delay: float = 1.0) -> None:
        self.link = link
        self.say = say or (lambda _text: None)
        self.ack_timeout = max(ack_timeout, 0.3 * link.clock.speedup)
        self.attempts, self.rejected_retries, self.retry_delay = (
            attempts, rejected_retries, retry_delay)
        self._acks: deque[Any] = deque(maxlen=32)
        self.ekf_flags: int | None = None
        self.last_local_position: float | None = None
        link.add_listener(self._on_message)

    def _on_message(self, msg: Any, t: float) -> None:
        kind = msg.get_type()
        if kind == "COMMAND_ACK":
            # An ACK to another ground station's command is not ours (MAVLink 2 target).
            target = getattr(msg, "target_system", 0)
            if target in (0, self.link.mav.srcSystem):
                self._acks.append(msg)
        elif kind == "EKF_STATUS_REPORT":
            self.ekf_flags = msg.flags
        elif kind == "LOCAL_POSITION_NED":
            self.last_local_position = t

    def _name(self, command: int) -> str:
        return self.link.enum_name("MAV_CMD", command)

    def command(self, command: int, params: tuple[float, ...] = (), what: str | None = None,
                retry_rejected: bool = True) -> None:
        """Send COMMAND_LONG ``command`` with up to 7 ``params`` until ACCEPTED.

        Raises
        ------
        CommandRejected
            Refused (DENIED, UNSUPPORTED, FAILED, …), or still TEMPORARILY_REJECTED after
            the retries; the message names the command and the result.
        JobFailedError
            No answer after `attempts` sends.
        """
        what = what or self._name(command)
        p = (*[float(x) for x in params], *[0.0] * (7 - len(params)))
        v = self.link.vehicle
        rejected = 0
        confirmation = 0
        while True:
            result = None
            for attempt in range(self.attempts):
                confirmation = min(255, confirmation + (attempt > 0))
                self._acks.clear()
                self.link.send(self.link.mav.command_long_encode(
                    v.system, v.component, command, confirmation, *p))
                result = self._wait_ack(command)
                if result is not None:
                    break
                self.say(f"{what}: no answer from the vehicle, sending again")
            if result is None:
                raise JobFailedError(f"{what}: no COMMAND_ACK from the vehicle after "
                                     f"{self.attempts} attempts")
            if result == _ACCEPTED:
                return
            name = self.link.enum_name("MAV_RESULT", result)
            if result == _TEMPORARILY_REJECTED and retry_rejected and (
                    rejected < self.rejected_retries):
                rejected += 1
                self.say(f"{what}: {name}, retrying ({rejected} of {self.rejected_retries})")
                self.link.poll(self.retry_delay)
                continue
            raise CommandRejected(f"{what} refused by the vehicle: {name}", command, result, name)

    def _wait_ack(self, command: int) -> int | None:
        deadline = self.link.clock.now() + self.ack_timeout
        while self.link.clock.now() < deadline:
            self.link.poll(min(0.05, self.ack_timeout))
            while self._acks:
                ack = self._acks.popleft()
                if ack.command != command:
                    continue
                if ack.result == _IN_PROGRESS:
                    deadline = self.link.clock.now() + self.ack_timeout
                    continue
                return int(ack.result)
        return None

    def _wait_heartbeat(self, condition: Callable[[], bool], seconds: float = 3.0) -> bool:
        """Poll until a heartbeat received from now on makes ``condition`` true."""
        start_count = self.link.vehicle.heartbeats
        deadline = self.link.clock.now() + seconds
        while self.link.clock.now() < deadline:
            self.link.poll(0.05)
            if self.link.vehicle.heartbeats > start_count and condition():
                return True
        return False

    # --- modes and arming ----------------------------------------------------------------

    def set_mode(self, name: str) -> None:
        """Switch to flight mode ``name`` (a key of the family's modes) and confirm it.

        Raises
        ------
        CommandRejected, JobFailedError
            Refused, unanswered, or accepted but never shown in a HEARTBEAT.
        """
        autopilot = self.link.vehicle.autopilot
        if autopilot is None:
            raise JobFailedError(f"cannot set mode {name}: unknown autopilot family")
        wanted = autopilot.modes[name]
        if autopilot is Autopilot.ARDUPILOT:
            params = (_CUSTOM_MODE_ENABLED, wanted)
        else:
            params = (_CUSTOM_MODE_ENABLED, (wanted >> 16) & 0xFF, (wanted >> 24) & 0xFF)
        self.command(MAV_CMD_DO_SET_MODE, params, what=f"mode {name}")
        if not self._wait_heartbeat(lambda: self.link.vehicle.custom_mode == wanted):
            raise JobFailedError(f"mode {name} was accepted but the vehicle still reports "
                                 f"{self.link.vehicle.mode}")

    def arm(self, attempts: int = 3, retry_delay: float = 2.0,
            explain: Callable[[], str] | None = None) -> None:
        """Arm the motors and wait for the HEARTBEAT to show it.

        ArduPilot answers an arm whose pre-arm checks fail with MAV_RESULT_FAILED (PX4:
        TEMPORARILY_REJECTED, retried by `command`): a check that is only not ready yet
        (EKF, GPS after a boot) passes seconds later, so FAILED is tried again, up to
        ``attempts`` arms ``retry_delay`` streamer s apart. DENIED is final.

        Parameters
        ----------
        explain : callable, optional
            Returns the autopilot's reason (its last "PreArm:" text), added to the
            one-line message of a refusal.

        Raises
        ------
        CommandRejected
            Still refused: names the MAV_RESULT and, with ``explain``, the reason.
        """
        for attempt in range(1, attempts + 1):
            try:
                self.command(MAV_CMD_COMPONENT_ARM_DISARM, (1,), what="arm")
                break
            except CommandRejected as error:
                self.link.poll(0.3)  # the autopilot's STATUSTEXT may trail its ACK
                why = "" if explain is None else f" ({explain()})"
                if error.result == _FAILED and attempt < attempts:
                    self.say(f"arm: {error.result_name}{why}, retrying ({attempt} of "
                             f"{attempts - 1})")
                    self.link.poll(retry_delay)
                    continue
                raise CommandRejected(f"{error}{why}", error.command, error.result,
                                      error.result_name) from None
        if not self._wait_heartbeat(lambda: self.link.vehicle.armed):
            raise JobFailedError("arming was accepted but the vehicle does not report armed")

    def takeoff(self, altitude: float) -> None:
        """MAV_CMD_NAV_TAKEOFF to ``altitude`` m above home (ArduPilot GUIDED, armed)."""
        self.command(MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, altitude),
                     what=f"take-off to {altitude:.2f} m")

    def set_message_interval(self, message: str, rate_hz: float) -> str | None:
        """Ask for ``message`` at ``rate_hz``; returns None if accepted, else why not."""
        msg_id = getattr(self.link.mavlink, f"MAVLINK_MSG_ID_{message}")
        try:
            self.command(MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, 1e6 / rate_hz),
                         what=f"{message} at {rate_hz:g} Hz")
        except CommandRejected as error:
            return error.result_name
        except JobFailedError as error:
            return str(error)
        return None

    def request_message(self, message: str) -> None:
        """Ask for one ``message`` now (MAV_CMD_REQUEST_MESSAGE); errors are ignored."""
        msg_id = getattr(self.link.mavlink, f"MAVLINK_MSG_ID_{message}")
        with contextlib.suppress(JobFailedError):
            self.command(MAV_CMD_REQUEST_MESSAGE, (msg_id,), retry_rejected=False)

    # --- position --------------------------------------------------------------------------

    def position_problem(self) -> str | None:
        """Why the vehicle has no usable local position yet, or None if it has one."""
        now = self.link.clock.now()
        if self.last_local_position is None or now - self.last_local_position > 1.5:
            return "no LOCAL_POSITION_NED yet"
        if self.link.vehicle.autopilot is Autopilot.ARDUPILOT and self.ekf_flags is not None:
            missing = [n for bit, n in _EKF_FLAG_NAMES.items() if not self.ekf_flags & bit]
            if missing:
                return f"EKF lacks {', '.join(missing)}"
            if self.ekf_flags & _EKF_CONST_POS_MODE:
                return "EKF in constant-position mode (no position source)"
        return None

    def wait_position(self, timeout: float) -> None:
        """Wait until the vehicle has a usable local position (see `position_problem`).

        ArduPilot: EKF_STATUS_REPORT with the position flags (when it sends that report)
        and a LOCAL_POSITION_NED in the last 1.5 s; PX4 sends LOCAL_POSITION_NED only
        with a valid estimate, so one is enough. Says what is missing every 5 s.

        Raises
        ------
        JobFailedError
            Still no position after ``timeout`` streamer s.
        """
        start = self.link.clock.now()
        next_note = start
        while (problem := self.position_problem()) is not None:
            now = self.link.clock.now()
            if now - start > timeout:
                raise JobFailedError(f"no usable local position within {timeout:g} s: "
                                     f"{problem}")
            if now >= next_note:
                self.say(f"waiting for a usable local position: {problem} "
                         f"({now - start:.0f} s of {timeout:g} s)")
                next_note += 5.0
            self.link.poll(0.1)
