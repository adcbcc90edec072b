"""Downloading the flight's own log from the autopilot over MAVLink, as ground stations do.

The log protocol (MAVLink common, "Log download"; ArduPilot's
``GCS_MAVLINK::handle_log_*``, PX4's ``MavlinkLogHandler``, MAVProxy's ``log`` module):

1. LOG_REQUEST_LIST (0, 0xFFFF) → one LOG_ENTRY (id, num_logs, last_log_num, time_utc,
   size) per log; a vehicle without logs answers one entry with ``num_logs`` 0. The
   request is repeated while entries are missing.
2. LOG_REQUEST_DATA (id, 0, size) for the newest log (the highest id: the flight
   just landed) → LOG_DATA (id, ofs, count, 90 bytes) until the end. Once the last chunk
   asked for has come, or nothing has come for `IDLE_SECONDS` (it was lost), the span from
   the first to the last missing chunk is asked for again (one LOG_REQUEST_DATA: a vehicle
   serves one request at a time, a new one replacing the old), at most `MAX_REQUESTS`
   requests in all; the vehicle sends 90-byte chunks from the offset asked, so what has
   come is tracked in 90-byte chunks.
3. LOG_REQUEST_END: the autopilot goes back to logging.

The file goes into the flight directory as ``autopilot.bin`` (a DataFlash log: it starts
with 0xA3 0x95) or ``autopilot.ulg`` (a ULog: ``ULog``), written atomically once complete;
an incomplete download is kept as ``autopilot.partial`` and said so. Timing is the link
clock's (streamer seconds), and the rate achieved is reported.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.formats.dataflash import HEADER
from mavsysid.formats.ulog import ULOG_MAGIC

from mavsysid.errors import JobFailedError

__all__ = ["CHUNK", "IDLE_SECONDS", "IMU_FAST", "MAX_REQUESTS", "LogDownload",
           "download_flight_log", "download_latest_log", "log_file_name", "log_imu_fast"]

#: Bytes of one LOG_DATA message.
CHUNK = 90
#: Link seconds without LOG_DATA after which missing stretches are asked for again.
IDLE_SECONDS = 1.0
#: LOG_REQUEST_DATA requests at most per download (the first included).
MAX_REQUESTS = 200
_LIST_TRIES, _LIST_WAIT = 3, 2.0  # LOG_REQUEST_LIST attempts, link s each


@dataclass(frozen=True)
class LogDownload:
    """A finished download.

    Attributes
    ----------
    path : Path
        The file written (``autopilot.bin``, ``.ulg``, or ``.partial`` when incomplete).
    log_id : int
        The vehicle's number of the log.
    size : int
        Bytes, as the vehicle listed it.
    received : int
        Bytes received.
    seconds : float
        Link seconds from the first data request to the last byte.
    requests : int
        LOG_REQUEST_DATA requests sent.
    """

    path: Path
    log_id: int
    size: int
    received: int
    seconds: float
    requests: int

    @property
    def complete(self) -> bool:
        """Whether every byte arrived."""
        return self.received == self.size

    @property
    def rate(self) -> float:
        """Bytes per link second."""
        return self.received / self.seconds if self.seconds > 0.0 else math.inf

    def summary(self) -> dict[str, Any]:
        """What meta.json records of it."""
        return {"file": self.path.name, "id": self.log_id, "size_bytes": self.size,
                "received_bytes": self.received, "complete": self.complete,
                "seconds": round(self.seconds, 3), "bytes_per_s": round(self.rate, 1),
                "requests": self.requests,
                "clock": "link seconds (wall × speedup) from the first LOG_REQUEST_DATA"}


def log_file_name(data: bytes) -> str:
    """``autopilot.bin`` for a DataFlash log, ``autopilot.ulg`` for a ULog, else
    ``autopilot.log``.

    Parameters
    ----------
    data : bytes
        The log's bytes (the first few decide).
    """
    if data.startswith(ULOG_MAGIC[:4]):
        return "autopilot.ulg"
    if data.startswith(HEADER):
        return "autopilot.bin"
    return "autopilot.log"


class _Receiver:
    """Collects LOG_ENTRY and LOG_DATA from the vehicle (a `MavlinkLink` listener)."""

    def __init__(self) -> None:
        self.entries: dict[int, Any] = {}
        self.listed: int | None = None
        self.log_id = 0
        self.buffer = bytearray()
        self.have = np.zeros(0, dtype=bool)
        self.last_data = -math.inf
        self.last_byte = -math.inf

    def start(self, log_id: int, size: int) -> None:
        self.log_id = log_id
        self.buffer = bytearray(size)
        self.have = np.zeros(-(-size // CHUNK), dtype=bool)

    def __call__(self, msg: Any, t: float) -> None:
        kind = msg.get_type()
        if kind == "LOG_ENTRY":
            self.listed = int(msg.num_logs)
            if msg.num_logs:
                self.entries[int(msg.id)] = msg
        elif kind == "LOG_DATA" and msg.id == self.log_id and self.have.size:
            self.last_data = t
            ofs, count = int(msg.ofs), int(msg.count)
            if ofs % CHUNK or count == 0 or ofs + count > len(self.buffer):
                return
            self.buffer[ofs:ofs + count] = bytes(msg.data[:count])
            self.have[ofs // CHUNK] = True
            self.last_byte = t

    def received(self) -> int:
        """Bytes received so far."""
        full = int(self.have.sum()) * CHUNK
        if self.have.size and self.have[-1]:
            full -= self.have.size * CHUNK - len(self.buffer)
        return full

    def missing(self) -> tuple[int, int] | None:
        """The span from the first to the last missing chunk, chunk indices [a, b); None
        when complete."""
        missing = np.flatnonzero(~self.have)
        return None if not missing.size else (int(missing[0]), int(missing[-1]) + 1)


def _list_logs(link: MavlinkLink, receiver: _Receiver) -> Any:
    """The newest LOG_ENTRY, or a JobFailedError saying why there is none."""
    system, component = link.vehicle.system, link.vehicle.component
    for _ in range(_LIST_TRIES):
        link.send(link.mav.log_request_list_encode(system, component, 0, 0xFFFF))
        deadline = link.clock.now() + _LIST_WAIT
        while link.clock.now() < deadline:
            link.poll(0.05)
            if receiver.listed == 0:
                raise JobFailedError("the vehicle lists no logs (is logging on? ArduPilot "
                                     "logs while armed unless LOG_DISARMED)")
            if receiver.listed is not None and len(receiver.entries) >= receiver.listed:
                break
        if receiver.entries:
            break
    if not receiver.entries:
        raise JobFailedError("the vehicle answered no LOG_REQUEST_LIST (LOG_ENTRY)")
    return receiver.entries[max(receiver.entries)]


def _fetch(link: MavlinkLink, receiver: _Receiver, timeout: float) -> tuple[int, float]:
    """Request the log's data until complete, out of requests or ``timeout`` link s;
    (requests sent, link s from the first request to the last byte)."""
    system, component = link.vehicle.system, link.vehicle.component
    start = link.clock.now()
    requests, last = 0, -1  # requests sent; the last chunk of the current one
    while (span := receiver.missing()) is not None and link.clock.now() - start < timeout:
        done = last >= 0 and receiver.have[last]
        idle = link.clock.now() - receiver.last_data >= IDLE_SECONDS
        if requests == 0 or done or idle:
            if requests >= MAX_REQUESTS:
                break
            first, end = span
            offset, length = first * CHUNK, min(end * CHUNK, len(receiver.buffer)) - first * CHUNK
            link.send(link.mav.log_request_data_encode(system, component, receiver.log_id,
                                                       offset, length))
            receiver.last_data, last = link.clock.now(), end - 1
            requests += 1
        link.poll(0.02)
    return requests, max(receiver.last_byte - start, 0.0)


def download_latest_log(link: MavlinkLink, directory: Path,
                        say: Callable[[str], None] | None = None,
                        min_rate: float = 2000.0) -> LogDownload:
    """Download the vehicle's newest log into ``directory`` (see the module docstring).

    Parameters
    ----------
    link : MavlinkLink
        A link whose vehicle heartbeat has been seen; the vehicle disarmed.
    directory : Path
        The flight directory.
    say : callable, optional
        Receives one-line progress messages.
    min_rate : float
        Bytes per link second below which the download is given up (the timeout is the
        listed size at this rate, plus 30 s).

    Returns
    -------
    LogDownload

    Raises
    ------
    JobFailedError
        No log listed, or not one byte received.
    """
    say = say or (lambda _text: None)
    receiver = _Receiver()
    link.add_listener(receiver)
    try:
        entry = _list_logs(link, receiver)
        size = int(entry.size)
        say(f"downloading log {entry.id} of {receiver.listed} ({size / 1e6:.2f} MB)")
        receiver.start(int(entry.id), size)
        requests, seconds = _fetch(link, receiver, 30.0 + size / min_rate)
    finally:
        link.send(link.mav.log_request_end_encode(link.vehicle.system, link.vehicle.component))
        link.remove_listener(receiver)
    received = receiver.received() if size else 0
    if received == 0 and size:
        raise JobFailedError(f"log {entry.id}: no data arrived ({requests} requests)")
    data = bytes(receiver.buffer)
    name = log_file_name(data) if received == size else "autopilot.partial"
    path = Path(directory) / name
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_bytes(data)
    os.replace(temporary, path)
    return LogDownload(path, int(entry.id), size, received, seconds, requests)


def download_flight_log(connect: str, directory: Path, signing_key: bytes | None = None,
                        speedup: float = 1.0, lockstep: bool = False,
                        heartbeat_timeout: float = 30.0,
                        say: Callable[[str], None] | None = None) -> LogDownload:
    """Open a link of its own to the landed vehicle and download its newest log.

    A link of its own, after the flight's is closed: the flight's ``flight.tlog`` records
    the flight, not the megabytes of LOG_DATA.

    Parameters
    ----------
    connect : str
        The vehicle's connection string.
    directory : Path
        The flight directory.
    signing_key : bytes, optional
        MAVLink 2 signing key.
    speedup : float
        A simulated vehicle's speedup.
    lockstep : bool
        Follow a simulated vehicle's lock-step frames.
    heartbeat_timeout : float
        Wall s to wait for the vehicle.
    say : callable, optional
        Receives one-line progress messages.

    Raises
    ------
    JobFailedError
        No vehicle, an armed vehicle (logs are read on the ground), or no log.
    """
    from mavsysid.flight.ground.link_clock import LinkClock

    link = MavlinkLink(connect, None, LinkClock(speedup, lockstep), signing_key)
    try:
        link.start_heartbeat()
        vehicle = link.wait_heartbeat(heartbeat_timeout, say)
        if vehicle.armed:
            raise JobFailedError("the vehicle is armed: its log is downloaded once landed")
        return download_latest_log(link, directory, say)
    finally:
        link.close()


#: LOG_BITMASK bit of ArduCopter's IMU_FAST: the IMU message at the loop rate, not 25 Hz.
IMU_FAST = 1 << 18


#: ArduPilot's IMU position (m, body FRD) and the low-pass its gyro and accelerometer logs
#: went through (Hz).
IMU_PARAMETERS = ("INS_POS1_X", "INS_POS1_Y", "INS_POS1_Z", "INS_GYRO_FILTER",
                  "INS_ACCEL_FILTER")


def log_imu_fast(parameters: Any, say: Callable[[str], None]) -> None:
    """Make an ArduPilot vehicle log its IMU at the loop rate for this flight.

    With LOG_BITMASK's IMU_FAST bit, ArduCopter writes its IMU message at the loop rate
    (400 Hz) instead of 25 Hz (``Copter::loop_rate_logging``), at once; the streamer puts
    LOG_BITMASK back after landing with the other parameters it changed. The IMU's
    position and filters (`IMU_PARAMETERS`) are read too, so that their PARAM_VALUEs are in
    the flight's tlog, whose reader takes them (`mavsysid.formats.tlog`).

    Parameters
    ----------
    parameters : ParameterSession
        The flight's parameter session (it remembers the value to restore).
    say : callable
        Receives a warning line when the vehicle has no LOG_BITMASK or refuses it.
    """
    value = parameters.read(["LOG_BITMASK", *IMU_PARAMETERS]).get("LOG_BITMASK")
    if value is None:
        say("warning: no LOG_BITMASK on the vehicle: its log keeps its own IMU rate")
        return
    try:
        parameters.set("LOG_BITMASK", float(int(value) | IMU_FAST))
    except JobFailedError as error:
        say(f"warning: LOG_BITMASK not set for a 400 Hz IMU in the log: {error}")
