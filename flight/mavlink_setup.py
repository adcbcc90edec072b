"""MAVLink set-up shared by the ground station and the simulated vehicle.

pymavlink's dialect, connection strings, the signing key and the ground station's identity.

pymavlink picks the wire protocol and dialect from the environment when ``mavutil`` is
imported, and a MAVLink 1 connection replaces its parser (losing the signing state) on
the first MAVLink 2 byte; so MAVLink 2 and ``ardupilotmega`` (which has ESC telemetry) are
set before any connection is opened.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

from mavsysid.errors import InputError

__all__ = ["DEFAULT_BAUD", "GCS_COMPONENT", "GCS_SYSTEM", "load_mavutil", "parse_connect",
           "signing_key_from_file"]

#: The ground station's MAVLink identity: system 255 (the usual GCS system id) and
#: MAV_COMP_ID_MISSIONPLANNER (190), the usual component id of a ground station.
GCS_SYSTEM = 255
GCS_COMPONENT = 190
#: Baud rate of a serial device given without one (a USB link to ArduPilot or PX4).
DEFAULT_BAUD = 115200


def load_mavutil() -> Any:
    """``pymavlink.mavutil`` set up for MAVLink 2 and the ``ardupilotmega`` dialect.

    The dialect module is chosen from the environment when ``mavutil`` is first imported;
    if it was imported before with other settings, it is switched here.
    """
    os.environ["MAVLINK20"] = "1"
    os.environ["MAVLINK_DIALECT"] = "ardupilotmega"
    from pymavlink import mavutil

    if mavutil.current_dialect != "ardupilotmega" or mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0":
        mavutil.set_dialect("ardupilotmega")
    return mavutil


def signing_key_from_file(path: str | Path) -> bytes:
    """The 32-byte MAVLink 2 signing key of a passphrase file: sha256(passphrase).

    The file holds the passphrase on one line (as MAVProxy's ``signing setup``);
    surrounding whitespace is ignored.

    Parameters
    ----------
    path : str or Path
        The passphrase file.

    Raises
    ------
    InputError
        An unreadable or empty file (one line).
    """
    try:
        text = Path(path).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"--signing-key {path}: cannot read the passphrase file: "
                         f"{getattr(error, 'strerror', None) or error}") from None
    if not text:
        raise InputError(f"--signing-key {path}: the passphrase file is empty")
    return hashlib.sha256(text.encode("utf-8")).digest()


def parse_connect(connect: str) -> tuple[str, int | None]:
    """Check a connection string; returns pymavlink's device and, for serial, the baud rate.

    Accepted: ``udp:HOST:PORT`` / ``udpin:HOST:PORT`` (listen), ``udpout:HOST:PORT``,
    ``tcp:HOST:PORT`` (connect), ``tcpin:HOST:PORT`` (listen), ``serial:DEVICE[:BAUD]``
    or a bare ``/dev/…[:BAUD]`` / ``COMn[:BAUD]`` device (115200 baud by default).

    Parameters
    ----------
    connect : str
        The connection string (forms below).

    Raises
    ------
    InputError
        Anything else (one line).
    """
    kind, _, rest = connect.partition(":")
    if kind in ("udp", "udpin", "udpout", "tcp", "tcpin"):
        host, _, port = rest.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise InputError(f"--connect {connect}: expected {kind}:HOST:PORT")
        return connect, None
    if kind == "serial" or connect.startswith("/dev/") or connect.upper().startswith("COM"):
        device = rest if kind == "serial" else connect
        head, _, tail = device.rpartition(":")
        if head and tail.isdigit():
            return head, int(tail)
        if device:
            return device, DEFAULT_BAUD
    raise InputError(f"--connect {connect}: expected udp:HOST:PORT, udpout:HOST:PORT, "
                     "tcp:HOST:PORT, tcpin:HOST:PORT or a serial device[:BAUD]")
