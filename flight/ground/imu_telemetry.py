"""The autopilot's IMU over the link: which message to ask for, at what rate, and its samples.

An autopilot sends its first IMU as ArduPilot's RAW_IMU (mG and mrad/s,
``GCS_MAVLINK::send_raw_imu``) or PX4's HIGHRES_IMU (SI floats); either may also send
SCALED_IMU (mG, mrad/s). `request_imu` asks for the autopilot's own message with
SET_MESSAGE_INTERVAL at `imu_rate`, the highest rate the link carries: a network link
(UDP, TCP) carries what the autopilot sends at most, `MAX_IMU_RATE`; a serial link at B
baud carries B/10 bytes/s, of which the IMU gets `SERIAL_SHARE`, one message of
`IMU_MESSAGE_BYTES` at a time. A refused rate is asked for again at half of it, down to
`MIN_IMU_RATE`. `ImuTelemetry` keeps the latest sample, body FLU (gyro
rad/s, specific force m/s², +9.81 on z level at rest), stamped with the autopilot's clock
(``time_usec`` or ``time_boot_ms``, s). RAW_IMU is read only from an ArduPilot autopilot
(its HEARTBEAT says so): elsewhere it carries raw sensor counts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.mavlink_setup import parse_connect
from mavsysid.formats.tlog import STANDARD_GRAVITY
from mavsysid.vehicle.frames import frd_to_flu

__all__ = ["IMU_MESSAGE_BYTES", "MAX_IMU_RATE", "MIN_IMU_RATE", "SERIAL_SHARE", "ImuSample",
           "ImuTelemetry", "imu_message", "imu_rate", "request_imu"]

#: Hz: the fastest ArduCopter sends a message, 0.8 × its 400 Hz loop
#: (``GCS_MAVLINK::cap_message_interval`` refuses shorter intervals: 400 Hz is DENIED).
MAX_IMU_RATE = 320.0
#: Hz: the slowest IMU rate asked for after refusals.
MIN_IMU_RATE = 10.0
#: Share of a serial link's bandwidth the IMU may take (the pose, attitude, ESC telemetry
#: and setpoints need the rest).
SERIAL_SHARE = 0.3
#: Bytes on the wire of one IMU message: its MAVLink 2 payload and 12 bytes of framing.
IMU_MESSAGE_BYTES = {"RAW_IMU": 29 + 12, "HIGHRES_IMU": 63 + 12}
_MAX_INT16 = 32767
_ARDUPILOT_ID = 3  # MAV_AUTOPILOT_ARDUPILOTMEGA


@dataclass(frozen=True)
class ImuSample:
    """One IMU sample.

    Attributes
    ----------
    t : float
        The autopilot's time of the sample, s.
    gyro : ndarray, shape (3,)
        Body rates, rad/s, body FLU.
    accel : ndarray, shape (3,)
        Specific force, m/s², body FLU.
    message : str
        The message it came in.
    """

    t: float
    gyro: np.ndarray
    accel: np.ndarray
    message: str


def imu_message(autopilot: Autopilot | None) -> str:
    """The IMU message an autopilot sends: RAW_IMU (ArduPilot), else HIGHRES_IMU.

    Parameters
    ----------
    autopilot : Autopilot or None
        The vehicle's autopilot family, from its heartbeat.
    """
    return "RAW_IMU" if autopilot is Autopilot.ARDUPILOT else "HIGHRES_IMU"


def imu_rate(connect: str, message: str, ceiling: float = MAX_IMU_RATE) -> float:
    """The rate of an IMU message a link carries, Hz (see the module docstring).

    Parameters
    ----------
    connect : str
        The connection string (`mavsysid.flight.mavlink_setup.parse_connect`).
    message : str
        A key of `IMU_MESSAGE_BYTES`.
    ceiling : float
        Hz, the most to ask for.
    """
    _, baud = parse_connect(connect)
    if baud is None:
        return ceiling
    return float(min(ceiling, SERIAL_SHARE * baud / 10.0 / IMU_MESSAGE_BYTES[message]))


def request_imu(set_interval: Callable[[str, float], str | None], autopilot: Autopilot | None,
                connect: str) -> tuple[str, float, str | None]:
    """Ask the vehicle for its IMU message at the rate the link carries.

    Parameters
    ----------
    set_interval : callable
        ``(message, rate_hz) → None or why refused``
        (`mavsysid.flight.ground.vehicle_commands.VehicleCommands.set_message_interval`).
    autopilot : Autopilot or None
        The vehicle's autopilot family.
    connect : str
        The link's connection string.

    Returns
    -------
    message : str
        The message asked for.
    rate : float
        Hz asked for.
    refusal : str or None
        Why the vehicle refused the last rate asked for, or None once one was accepted.
    """
    message = imu_message(autopilot)
    rate = imu_rate(connect, message)
    while (refusal := set_interval(message, rate)) is not None and rate / 2.0 >= MIN_IMU_RATE:
        rate /= 2.0
    return message, rate, refusal


class ImuTelemetry:
    """The latest IMU sample from the vehicle's messages (see the module docstring).

    Attributes
    ----------
    latest : ImuSample or None
        The last sample received.
    count : int
        Samples received.
    """

    def __init__(self) -> None:
        self.latest: ImuSample | None = None
        self.count = 0
        self._ardupilot = False

    def on_message(self, msg: Any) -> bool:
        """Take ``msg`` if it is an IMU message of the first IMU; whether it was one.

        Parameters
        ----------
        msg : pymavlink message
            A message from the vehicle (its HEARTBEAT tells ArduPilot's RAW_IMU apart).
        """
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self._ardupilot = int(msg.autopilot) == _ARDUPILOT_ID
            return False
        if kind not in ("HIGHRES_IMU", "SCALED_IMU", "RAW_IMU"):
            return False
        # HIGHRES_IMU and RAW_IMU name their IMU in a field ``id`` (not the message id).
        second = "id" in msg.get_fieldnames() and int(msg.id or 0) != 0
        if second or (kind == "RAW_IMU" and not self._ardupilot):
            return True  # another IMU, or raw sensor counts
        if kind == "HIGHRES_IMU":
            if (int(msg.fields_updated) & 0b111111) not in (0, 0b111111):
                return True  # a partial update repeats stale values of the other sensor
            gyro, accel = [msg.xgyro, msg.ygyro, msg.zgyro], [msg.xacc, msg.yacc, msg.zacc]
            t = msg.time_usec * 1e-6
        else:
            milli = [msg.xgyro, msg.ygyro, msg.zgyro, msg.xacc, msg.yacc, msg.zacc]
            if any(abs(v) >= _MAX_INT16 for v in milli):
                return True  # saturated int16: not a reading
            gyro = [v * 1e-3 for v in milli[:3]]
            accel = [v * 1e-3 * STANDARD_GRAVITY for v in milli[3:]]
            t = msg.time_boot_ms * 1e-3 if kind == "SCALED_IMU" else msg.time_usec * 1e-6
        values = np.array([*gyro, *accel], dtype=float)
        if not np.isfinite(values).all():
            return True
        self.latest = ImuSample(t, frd_to_flu(values[:3]), frd_to_flu(values[3:]), kind)
        self.count += 1
        return True
