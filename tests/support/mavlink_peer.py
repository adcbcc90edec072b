"""A scripted MAVLink vehicle for link-level tests: real UDP on 127.0.0.1, pymavlink.

`ScriptedVehicle` runs a pymavlink connection in a thread, as system 1 component 1: it
sends HEARTBEATs (ArduPilot or PX4, a mode, armed or not) and whatever a test queues,
answers each COMMAND_LONG with the result a test's ``answer`` function returns (None:
stay silent), and keeps every message it received.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from mavsysid.flight.mavlink_setup import load_mavutil

__all__ = ["ScriptedVehicle"]



class ScriptedVehicle:
    """A fake vehicle sending to ``udpout:127.0.0.1:PORT`` (see the module docstring).

    Parameters
    ----------
    port : int
        The ground station's UDP port.
    autopilot : int
        HEARTBEAT.autopilot (3 ArduPilot, 12 PX4).
    mav_type : int
        HEARTBEAT.type (13 hexarotor).
    heartbeat_period : float
        s; 0 sends none.
    answer : callable, optional
        ``answer(command_long_msg) -> MAV_RESULT or None``; default: ACCEPTED.
    signing_key : bytes, optional
        Sign outgoing messages and accept only signed ones.
    """

    def __init__(self, port: int, autopilot: int = 3, mav_type: int = 13,
                 heartbeat_period: float = 0.2,
                 answer: Callable[[Any], int | None] | None = None,
                 signing_key: bytes | None = None) -> None:
        mavutil = load_mavutil()
        self.mavlink = mavutil.mavlink
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                               source_component=1)
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True)
        self.autopilot, self.mav_type = autopilot, mav_type
        self.base_mode, self.custom_mode = 1, 0
        self.heartbeat_period = heartbeat_period
        self.answer = answer or (lambda _msg: 0)
        self.received: list[Any] = []
        self.on_command: Callable[[Any], None] | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> ScriptedVehicle:
        """Start sending and answering."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the socket."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.conn.close()

    def __enter__(self) -> ScriptedVehicle:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def send(self, msg: Any) -> None:
        """Send one message (thread-safe)."""
        with self._lock:
            self.conn.mav.send(msg)

    def heartbeat(self) -> None:
        """Send one HEARTBEAT with the current mode and armed state."""
        self.send(self.conn.mav.heartbeat_encode(self.mav_type, self.autopilot, self.base_mode,
                                                 self.custom_mode, 4))

    def received_of(self, kind: str) -> list[Any]:
        """Messages of one type received so far."""
        with self._lock:
            return [m for m in self.received if m.get_type() == kind]

    def _run(self) -> None:
        next_beat = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if self.heartbeat_period > 0 and now >= next_beat:
                self.heartbeat()
                next_beat = now + self.heartbeat_period
            msg = self.conn.recv_msg()
            if msg is None:
                self.conn.select(0.01)
                continue
            if msg.get_type() == "BAD_DATA":
                continue
            with self._lock:
                self.received.append(msg)
            if msg.get_type() == "COMMAND_LONG":
                if self.on_command is not None:
                    self.on_command(msg)
                result = self.answer(msg)
                if result is not None:
                    self.send(self.conn.mav.command_ack_encode(
                        msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()))
