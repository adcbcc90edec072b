"""Commands to the simulated vehicle (COMMAND_LONG / COMMAND_INT) and their results.

Every command gets a COMMAND_ACK: ACCEPTED, DENIED, TEMPORARILY_REJECTED, FAILED as
the autopilot decides (`mavsysid.flight.simvehicle.autopilot`), UNSUPPORTED for commands the
simulation
does not know. Commands that ask for a message (REQUEST_MESSAGE, GET_HOME_POSITION,
REQUEST_AUTOPILOT_CAPABILITIES, GET_MESSAGE_INTERVAL) return it after the ACK.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES, PX4_MODES, px4_custom_mode
from mavsysid.flight.simvehicle.autopilot import SimAutopilot
from mavsysid.flight.simvehicle.link import mavlink
from mavsysid.flight.simvehicle.telemetry import (
    MessageScheduler,
    TelemetryBuilder,
    ardupilot_streams,
)

__all__ = ["FORCE_MAGIC", "CommandHandler"]

M = mavlink
#: param2 of COMPONENT_ARM_DISARM that skips the checks.
FORCE_MAGIC = 21196
_STREAM_PARAMS = {"SR0_EXT_STAT": M.MAV_DATA_STREAM_EXTENDED_STATUS,
                  "SR0_POSITION": M.MAV_DATA_STREAM_POSITION,
                  "SR0_EXTRA1": M.MAV_DATA_STREAM_EXTRA1, "SR0_EXTRA3": M.MAV_DATA_STREAM_EXTRA3,
                  "SR0_RAW_SENS": M.MAV_DATA_STREAM_RAW_SENSORS}


def _int(value: float) -> int:
    """An integer parameter; 0 for NaN (ground stations such as MAVSDK send NaN for
    parameters they leave unset)."""
    return int(value) if math.isfinite(value) else 0


class CommandHandler:
    """Carries out commands and stream requests.

    Parameters
    ----------
    autopilot : SimAutopilot
    scheduler : MessageScheduler
    builder : TelemetryBuilder
    """

    def __init__(self, autopilot: SimAutopilot, scheduler: MessageScheduler,
                 builder: TelemetryBuilder) -> None:
        self.ap = autopilot
        self.scheduler = scheduler
        self.builder = builder
        self.streams = ardupilot_streams() if autopilot.ardupilot else {}
        self._handlers = {
            M.MAV_CMD_COMPONENT_ARM_DISARM: self._arm,
            M.MAV_CMD_DO_SET_MODE: self._set_mode,
            M.MAV_CMD_NAV_TAKEOFF: lambda p: (self.ap.takeoff(p[6]), []),
            M.MAV_CMD_NAV_LAND: lambda p: (self._mode_named("LAND"), []),
            M.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda p: (self._mode_named("RTL"), []),
            M.MAV_CMD_SET_MESSAGE_INTERVAL: self._set_interval,
            M.MAV_CMD_GET_MESSAGE_INTERVAL: self._get_interval,
            M.MAV_CMD_REQUEST_MESSAGE: lambda p: self._send_message(int(p[0])),
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
                lambda p: self._send_message(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION),
            M.MAV_CMD_GET_HOME_POSITION:
                lambda p: self._send_message(M.MAVLINK_MSG_ID_HOME_POSITION),
        }
        if self.streams:
            autopilot.params.add_listener(self._stream_parameter)

    def command(self, command: int, params: Sequence[float]) -> tuple[int, list]:
        """Run one command with its seven parameters; (MAV_RESULT, messages to send after
        the ACK)."""
        handler = self._handlers.get(command)
        if handler is None:
            return M.MAV_RESULT_UNSUPPORTED, []
        try:
            return handler(list(params))
        except (ValueError, OverflowError):  # NaN or infinite where a number is needed
            return M.MAV_RESULT_DENIED, []

    def set_mode_message(self, base_mode: int, custom_mode: int) -> int:
        """The SET_MODE message (#11); the MAV_RESULT for its (ArduPilot-style) ACK."""
        if not base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return M.MAV_RESULT_FAILED
        return self.ap.set_mode(custom_mode)

    def request_data_stream(self, stream_id: int, rate_hz: float, start: bool) -> None:
        """REQUEST_DATA_STREAM (ArduPilot only): set a stream group's rate, or all."""
        if not self.streams:
            return
        rate = rate_hz if start else 0.0
        groups = self.streams.values() if stream_id == M.MAV_DATA_STREAM_ALL else (
            [self.streams[stream_id]] if stream_id in self.streams else [])
        for ids in groups:
            self.scheduler.set_rate_hz(ids, rate, self.ap.vehicle.time_us)

    # --- handlers ------------------------------------------------------------------------
    def _arm(self, p: list[float]) -> tuple[int, list]:
        return self.ap.arm(p[0] > 0.5, force=_int(p[1]) == FORCE_MAGIC), []

    def _set_mode(self, p: list[float]) -> tuple[int, list]:
        if not _int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return M.MAV_RESULT_FAILED, []
        if self.ap.ardupilot:
            return self.ap.set_mode(int(p[1])), []
        main, sub = int(p[1]), _int(p[2])
        return self.ap.set_mode(px4_custom_mode(main, sub if main == 4 else 0)), []

    def _mode_named(self, name: str) -> int:
        if self.ap.ardupilot:
            return self.ap.set_mode(ARDUCOPTER_MODES[name])
        return self.ap.set_mode(px4_custom_mode(4, 5) if name == "RTL" else PX4_MODES[name])

    def _set_interval(self, p: list[float]) -> tuple[int, list]:
        msg_id = int(p[0])
        if not self.scheduler.set_interval(msg_id, p[1], self.ap.vehicle.time_us):
            return M.MAV_RESULT_UNSUPPORTED, []
        return M.MAV_RESULT_ACCEPTED, []

    def _get_interval(self, p: list[float]) -> tuple[int, list]:
        msg_id = int(p[0])
        reply = M.MAVLink_message_interval_message(msg_id, self.scheduler.interval_us(msg_id))
        return M.MAV_RESULT_ACCEPTED, [reply]

    def _send_message(self, msg_id: int) -> tuple[int, list]:
        msg = self.builder.build(msg_id)
        if msg is None:
            return M.MAV_RESULT_FAILED, []
        return M.MAV_RESULT_ACCEPTED, [msg]

    def _stream_parameter(self, name: str, value: float) -> None:
        stream = _STREAM_PARAMS.get(name)
        if stream is not None:
            self.scheduler.set_rate_hz(self.streams[stream], value, self.ap.vehicle.time_us)
