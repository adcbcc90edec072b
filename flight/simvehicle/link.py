"""The simulated vehicle's MAVLink link: its identity and connection strings.

pymavlink is set up for MAVLink 2 and ArduPilot's dialect by `mavsysid.flight.mavlink_setup`,
shared with the streamer, as is the signing key (`signing_key_from_file`). Besides UDP and
TCP the vehicle talks on a serial device, as an autopilot on a USB cable or a telemetry
radio does (pyserial through pymavlink; a pseudo-terminal works the same).
"""

from __future__ import annotations

import re

from mavsysid.flight.mavlink_setup import load_mavutil, parse_connect

from mavsysid.errors import InputError

__all__ = ["COMPONENT_ID", "SYSTEM_ID", "mavlink", "mavutil", "open_link"]

mavutil = load_mavutil()
mavlink = mavutil.mavlink

#: The vehicle's MAVLink identity: system 1, MAV_COMP_ID_AUTOPILOT1.
SYSTEM_ID = 1
COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1

_CONNECT_RE = re.compile(r"^(udpout|udpin|udp|tcpin|tcp):([^:]+):(\d{1,5})$")


def open_link(connect: str):
    """Open ``udpout:HOST:PORT``, ``udpin:HOST:PORT``, ``tcpin:HOST:PORT`` or a serial
    device (``serial:DEVICE[:BAUD]``, ``/dev/…[:BAUD]``) as the vehicle.

    Returns
    -------
    pymavlink.mavutil.mavfile
        Non-blocking, MAVLink 2, system 1 component 1.

    Raises
    ------
    InputError
        A malformed connection string, or an address that cannot be opened.
    """
    device, baud = _device(connect)
    load_mavutil()  # in case another dialect was loaded since import
    options = {} if baud is None else {"baud": baud}
    try:
        link = mavutil.mavlink_connection(device, source_system=SYSTEM_ID,
                                          source_component=COMPONENT_ID, **options)
    except OSError as error:
        raise InputError(f"--connect {connect!r}: {error.strerror or error}") from None
    if link.WIRE_PROTOCOL_VERSION != "2.0":
        raise RuntimeError("pymavlink did not load MAVLink 2")
    return link


def _device(connect: str) -> tuple[str, int | None]:
    """pymavlink's device string of ``connect`` and, for a serial device, its baud rate."""
    match = _CONNECT_RE.match(connect)
    if match is None:
        try:
            device, baud = parse_connect(connect)
        except InputError:
            device, baud = "", None
        if baud is not None:
            return device, baud
    if match is None or not 0 < int(match.group(3)) < 65536:
        raise InputError(f"--connect {connect!r}: expected udpout:HOST:PORT, udpin:HOST:PORT, "
                         "tcpin:HOST:PORT or a serial device[:BAUD] (e.g. "
                         "udpout:127.0.0.1:14550, /dev/ttyUSB0:57600)")
    if match.group(1) in ("udp", "tcp"):
        raise InputError(f"--connect {connect!r}: a vehicle sends with udpout: or listens "
                         "with udpin:/tcpin:; udp:/tcp: are ground-station forms")
    return connect, None
