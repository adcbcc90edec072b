"""Tests of the ground station's MAVLink setup: connection strings and the signing key."""

from __future__ import annotations

import hashlib

import pytest
from mavsysid.flight.mavlink_setup import load_mavutil, parse_connect, signing_key_from_file

from mavsysid.errors import InputError


def test_signing_key_file(tmp_path):
    """The key is sha256 of the passphrase without surrounding whitespace."""
    path = tmp_path / "key"
    path.write_text("  correct horse battery staple \n", encoding="utf-8")
    assert signing_key_from_file(path) == hashlib.sha256(b"correct horse battery staple").digest()
    (tmp_path / "empty").write_text("\n", encoding="utf-8")
    with pytest.raises(InputError, match="empty"):
        signing_key_from_file(tmp_path / "empty")
    with pytest.raises(InputError, match="cannot read"):
        signing_key_from_file(tmp_path / "missing")


@pytest.mark.parametrize(("connect", "expected"), [
    ("udp:127.0.0.1:14550", ("udp:127.0.0.1:14550", None)),
    ("tcpin:0.0.0.0:5760", ("tcpin:0.0.0.0:5760", None)),
    ("serial:/dev/ttyACM0:921600", ("/dev/ttyACM0", 921600)),
    ("serial:/dev/ttyACM0", ("/dev/ttyACM0", 115200)),
    ("/dev/ttyUSB1", ("/dev/ttyUSB1", 115200)),
    ("/dev/ttyACM0:57600", ("/dev/ttyACM0", 57600)),
    ("COM3:57600", ("COM3", 57600)),
])
def test_connection_strings(connect, expected):
    """Network forms pass through; serial ones, bare or not, give the device and a baud rate."""
    assert parse_connect(connect) == expected


def test_mavlink2_and_ardupilot_dialect():
    """pymavlink is set up for MAVLink 2 with ArduPilot's ESC telemetry messages."""
    mavutil = load_mavutil()
    assert mavutil.mavlink.WIRE_PROTOCOL_VERSION == "2.0"
    assert hasattr(mavutil.mavlink, "MAVLink_esc_telemetry_5_to_8_message")
