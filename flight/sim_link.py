"""The simulated vehicle's MAVLink link: pymavlink set up for MAVLink 2 and ArduPilot's
dialect, connection strings, and the signing key.

pymavlink picks the wire protocol from the environment when a dialect is loaded, and a
connection opened as MAVLink 1 replaces its parser (and with it the signing state) on
the first MAVLink 2 byte it receives; so MAVLink 2 is forced here, before any
connection exists.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

os.environ["MAVLINK20"] = "1"
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicle.errors import InputError

__all__ = ["COMPONENT_ID", "SYSTEM_ID", "mavlink", "mavutil", "open_link", "read_signing_key"]

#: The vehicle's MAVLink identity: system 1, MAV_COMP_ID_AUTOPILOT1.
SYSTEM_ID = 1
COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1

_CONNECT_RE = re.compile(r"^(udpout|udpin|udp|tcpin|tcp):([^:]+):(\d{1,5})$")


def open_link(connect: str):
    """Open ``udpout:HOST:PORT``, ``udpin:HOST:PORT`` or ``tcpin:HOST:PORT`` as the vehicle.

    Returns
    -------
    pymavlink.mavutil.mavfile
        Non-blocking, MAVLink 2, system 1 component 1.

    Raises
    ------
    InputError
        A malformed connection string, or an address that cannot be opened.
    """
    match = _CONNECT_RE.match(connect)
    if match is None or not 0 < int(match.group(3)) < 65536:
        raise InputError(f"--connect {connect!r}: expected udpout:HOST:PORT, udpin:HOST:PORT "
                         "or tcpin:HOST:PORT (e.g. udpout:127.0.0.1:14550)")
    if match.group(1) in ("udp", "tcp"):
        raise InputError(f"--connect {connect!r}: a vehicle sends with udpout: or listens "
                         "with udpin:/tcpin:; udp:/tcp: are ground-station forms")
    mavutil.set_dialect("ardupilotmega")
    try:
        link = mavutil.mavlink_connection(connect, source_system=SYSTEM_ID,
                                          source_component=COMPONENT_ID)
    except OSError as error:
        raise InputError(f"--connect {connect!r}: {error.strerror or error}") from None
    if link.WIRE_PROTOCOL_VERSION != "2.0":
        raise RuntimeError("pymavlink did not load MAVLink 2")
    return link


def read_signing_key(path: str | Path) -> bytes:
    """The 32-byte MAVLink 2 secret key from a passphrase file (sha256 of its text).

    The same derivation as MAVProxy's ``signing setup PASSPHRASE``.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"--signing-key {path}: cannot read the passphrase file: "
                         f"{getattr(error, 'strerror', None) or error}") from None
    passphrase = text.strip()
    if not passphrase:
        raise InputError(f"--signing-key {path}: the file holds no passphrase")
    return hashlib.sha256(passphrase.encode("utf-8")).digest()
