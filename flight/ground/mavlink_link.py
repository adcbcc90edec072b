"""A MAVLink 2 link to one vehicle: connection, recording, GCS heartbeat, vehicle state.

`MavlinkLink` wraps a pymavlink connection (UDP, TCP or serial) with what a ground
station streaming setpoints needs and pymavlink leaves to its caller:

- every message, in both directions, recorded into a ``.tlog`` as it passes (pymavlink's
  own log holds the incoming ones only);
- a GCS HEARTBEAT at 1 Hz from a thread of its own, so that the autopilot's GCS failsafe
  can tell when the ground station is gone, whatever the main thread is doing;
- the vehicle's last HEARTBEAT (family, mode, armed) and how long ago it came;
- optional MAVLink 2 signing;
- a receive pump, `poll`, that also fires one periodic `Ticker` (the setpoint stream) on
  time, so that waiting for anything (an ACK, an altitude) never pauses the stream.

Receiving happens only inside `poll`, on the caller's thread: message handling and the
setpoint schedule never compete for the interpreter lock, which keeps the stream's timing
tight. Only sending is shared with the heartbeat thread, under a lock.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.ground.link_state import (
    MIN_SILENCE_WALL,
    HeartbeatLost,
    LinkClosed,
    VehicleState,
    link_loss_problem,
)
from mavsysid.flight.mavlink_setup import GCS_COMPONENT, GCS_SYSTEM, load_mavutil, parse_connect
from mavsysid.formats.tlog import TlogWriter

from mavsysid.errors import JobFailedError

__all__ = ["HeartbeatLost", "LinkClosed", "MavlinkLink", "Ticker", "VehicleState"]

_LONGEST_WAIT = 0.05  # wall s per select(): bounds how late an interrupt is noticed


class Ticker(Protocol):
    """A periodic job driven by `MavlinkLink.poll` (the setpoint stream)."""

    def next_deadline(self) -> float:
        """Streamer time (s) at which `fire` is next due."""

    def fire(self, now: float) -> None:
        """Do the job; ``now`` is the streamer time, s."""


Listener = Callable[[Any, float], None]


class MavlinkLink:
    """A MAVLink 2 connection to one vehicle (see the module docstring).

    Parameters
    ----------
    connect : str
        ``udp:HOST:PORT`` or ``udpin:HOST:PORT`` (listen), ``udpout:HOST:PORT``,
        ``tcp:HOST:PORT`` (connect), ``tcpin:HOST:PORT``, or a serial device
        ``/dev/ttyACM0`` / ``serial:/dev/ttyACM0:921600``.
    tlog : Path, optional
        Where to record both directions (created; must not exist).
    clock : LinkClock, optional
        Streamer time (scaled by the speedup); a fresh one by default.
    signing_key : bytes, optional
        32-byte MAVLink 2 secret key: sign everything sent, accept only signed messages.
    heartbeat_loss : float
        The vehicle is lost after this long without its HEARTBEAT, streamer s.
    link_loss : float
        ... or after this long without any message, once `watch_silence` is set, streamer
        s (never below `MIN_SILENCE_WALL` wall s; see `mavsysid.flight.ground.link_state`).
    spin : float
        Wall seconds before a tick that `poll` spends polling without sleeping: waking
        from a sleep can take milliseconds on a busy machine, a spin does not.

    Attributes
    ----------
    vehicle : VehicleState
        Its last heartbeat (``system`` 0 until one came).
    rejected_signed, rejected_unsigned : int
        Incoming messages dropped for a wrong signature / for having none.
    unverified_signed : int
        Signed messages accepted without a key to check them (the vehicle signs; we don't).
    watch_heartbeat : bool
        Whether `poll` raises `HeartbeatLost` (off until the flight wants it).
    watch_silence : bool
        Whether `poll` also raises it after `link_loss` s without any message (set once
        the telemetry streams).
    interrupt_pending : bool
        Set by a signal handler: the next `poll` raises `KeyboardInterrupt` (once).
    """

    def __init__(self, connect: str, tlog: Path | None = None, clock: LinkClock | None = None,
                 signing_key: bytes | None = None, heartbeat_loss: float = 3.0,
                 spin: float = 0.0, link_loss: float = 1.0) -> None:
        self.mavutil = load_mavutil()
        self.clock = clock or LinkClock()
        self.connect = connect
        self.heartbeat_loss = heartbeat_loss
        self.link_loss = max(link_loss, MIN_SILENCE_WALL * self.clock.speedup)
        self.spin = spin
        self.vehicle = VehicleState()
        self.rejected_signed = self.rejected_unsigned = self.unverified_signed = 0
        self.watch_heartbeat = self.watch_silence = False
        self.interrupt_pending = False
        self._interrupt_delivered = False
        self._listeners: list[Listener] = []
        self._ticker: Ticker | None = None
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._beat_thread: threading.Thread | None = None
        self._conn = self._open(connect)
        self._tlog = TlogWriter(tlog, self.clock) if tlog is not None else None
        self._conn.mav.set_send_callback(self._record_sent)
        if signing_key is not None:
            self._conn.setup_signing(signing_key, sign_outgoing=True)

    # --- connection ----------------------------------------------------------------------

    def _open(self, connect: str) -> Any:
        device, baud = parse_connect(connect)
        opts: dict[str, Any] = {"source_system": GCS_SYSTEM, "source_component": GCS_COMPONENT}
        if baud is not None:
            opts["baud"] = baud
        elif device.startswith("tcp:"):
            opts["retries"] = 1  # a refused connection is reported, not retried for seconds
        try:
            conn = self.mavutil.mavlink_connection(device, **opts)
        except OSError as error:
            raise JobFailedError(f"cannot open {connect}: {error.strerror or error}") from None
        if device.startswith("tcp:"):  # pymavlink's hooks for a closed socket
            conn.handle_eof = conn.handle_disconnect = self._closed
        if baud is not None:
            self._watch_serial(conn)
        return conn

    def _watch_serial(self, conn: Any) -> None:
        """A serial device that fails (unplugged, the radio's USB reset) ends the link in
        one line: pymavlink would print to stdout and carry on writing into nothing, and
        pyserial raise from the next read."""
        read, write = conn.recv, conn.port.write

        def recv(n: int | None = None) -> bytes:
            try:
                return read(n)
            except OSError as error:
                raise self._device_gone(error) from None

        def send(buf: bytes) -> int:
            try:
                return write(bytes(buf))
            except OSError as error:
                raise self._device_gone(error) from None

        conn.recv, conn.write = recv, send

    def _device_gone(self, error: OSError) -> LinkClosed:
        return LinkClosed(f"the serial device {self.connect} stopped working "
                          f"({error.strerror or error}); stopped, the vehicle is left to its "
                          "own failsafe")

    def _closed(self) -> None:
        raise LinkClosed(f"the link {self.connect} was closed by the other end; stopped, the "
                         "vehicle is left to its own failsafe")

    @property
    def mav(self) -> Any:
        """The pymavlink ``MAVLink`` object: its ``*_encode`` methods build messages."""
        return self._conn.mav

    @property
    def mavlink(self) -> Any:
        """The dialect module (enums, message ids)."""
        return self.mavutil.mavlink

    def start_heartbeat(self, period: float = 1.0) -> None:
        """Send a GCS HEARTBEAT every ``period`` streamer seconds from a daemon thread."""
        if self._beat_thread is not None:
            return
        M = self.mavlink
        msg_args = (M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)

        def beat() -> None:
            # Due times on a fixed grid, so that a late wake-up (a busy main thread holds
            # the GIL) does not push every later beat back; after a stall of more than a
            # period the grid restarts from now instead of sending a burst.
            wall_period = self.clock.wall(period)
            due = time.monotonic()
            while not self._stop.is_set():
                try:
                    self.send(self.mav.heartbeat_encode(*msg_args))
                except (OSError, ValueError, LinkClosed):
                    return  # the link was closed under us
                now = time.monotonic()
                due = due + wall_period if due + wall_period > now else now + wall_period
                self._stop.wait(due - now)

        self._beat_thread = threading.Thread(target=beat, name="gcs-heartbeat", daemon=True)
        self._beat_thread.start()

    def close(self) -> None:
        """Stop the heartbeat, close the connection and the tlog. Harmless twice."""
        self._stop.set()
        if self._beat_thread is not None:
            self._beat_thread.join(timeout=2.0)
        with self._send_lock:
            with contextlib.suppress(OSError):
                self._conn.close()
            if self._tlog is not None:
                self._tlog.close()

    def __enter__(self) -> MavlinkLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- sending -------------------------------------------------------------------------

    def send(self, msg: Any) -> None:
        """Send one message (thread-safe); it is recorded in the tlog."""
        with self._send_lock:
            self._conn.mav.send(msg)

    def _record_sent(self, msg: Any) -> None:
        if self._tlog is not None:
            self._tlog.write(msg.get_msgbuf())

    def set_ticker(self, ticker: Ticker | None) -> None:
        """Fire ``ticker`` on time from every `poll` from now on; None stops it."""
        self._ticker = ticker

    @property
    def ticker(self) -> Ticker | None:
        """The periodic job `poll` fires, if any."""
        return self._ticker

    # --- receiving -----------------------------------------------------------------------

    def add_listener(self, listener: Listener) -> None:
        """Call ``listener(msg, t)`` for every message from the vehicle's system.

        ``t`` is the streamer time of receipt, s. Listeners run in the order added; one
        that raises stops `poll` with that exception (a flight guard does so on purpose).
        """
        self._listeners.append(listener)

    def remove_listener(self, listener: Listener) -> None:
        """Stop calling ``listener`` (no error if it was not added)."""
        if listener in self._listeners:
            self._listeners.remove(listener)

    def poll(self, duration: float) -> None:
        """Receive and handle messages for ``duration`` streamer seconds.

        The ticker fires whenever due, before the next message is handled. With
        `watch_heartbeat` set, raises `HeartbeatLost` once the vehicle's heartbeat is
        older than `heartbeat_loss`.
        """
        self.poll_until(self.clock.now() + duration)

    def poll_until(self, deadline: float) -> None:
        """Like `poll`, until the streamer time ``deadline``, s."""
        while True:
            if self.interrupt_pending and not self._interrupt_delivered:
                self._interrupt_delivered = True
                raise KeyboardInterrupt
            now = self.clock.now()
            self._check_heartbeat(now)  # before a setpoint goes out: none into a dead link
            ticker = self._ticker
            if ticker is not None and now >= ticker.next_deadline():
                ticker.fire(now)
                continue
            msg = self._conn.recv_msg()
            if msg is not None:
                self._handle(msg)
                continue
            now = self.clock.now()
            if now >= deadline:
                return
            if (ack := self.clock.take_ack()) is not None:  # lock-step: caught up, about to wait
                self.send(self.mav.system_time_encode(ack * 1000, ack))
            wake = deadline
            if ticker is not None:
                wake = min(deadline, ticker.next_deadline() - self.spin * self.clock.speedup)
            self._conn.select(min(_LONGEST_WAIT, max(0.0, self.clock.wall(wake - now))))

    def heartbeat_age(self) -> float | None:
        """Streamer seconds since the vehicle's last HEARTBEAT (None before the first)."""
        last = self.vehicle.last_heartbeat
        return None if last is None else self.clock.now() - last

    def _check_heartbeat(self, now: float) -> None:
        if not self.watch_heartbeat:
            return
        problem = link_loss_problem(self.vehicle, now, self.heartbeat_loss,
                                    self.link_loss if self.watch_silence else None)
        if problem is not None:
            raise HeartbeatLost(f"{problem}; stopped streaming, the vehicle is left to its "
                                "own failsafe")

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            if "signature" in str(getattr(msg, "reason", "")):
                data = getattr(msg, "data", b"")
                signed = len(data) > 2 and data[0] == 253 and data[2] & 1
                if signed:
                    self.rejected_signed += 1
                else:
                    self.rejected_unsigned += 1
            return
        self.clock.observe(msg)  # lock-step frames set the clock (LinkClock)
        t = self.clock.received(msg)
        if self._tlog is not None:
            self._tlog.write(msg.get_msgbuf())
        # Without a key pymavlink reads signed packets unchecked and calls them unsigned.
        if self._conn.mav.signing.secret_key is None and msg.get_header().incompat_flags & 1:
            self.unverified_signed += 1
        system = msg.get_srcSystem()
        if kind == "HEARTBEAT" and self._is_vehicle_heartbeat(msg):
            self._note_heartbeat(msg, t)
        if system != self.vehicle.system or self.vehicle.system == 0:
            return
        self.vehicle.last_message = t
        for listener in tuple(self._listeners):
            listener(msg, t)

    def _is_vehicle_heartbeat(self, msg: Any) -> bool:
        M = self.mavlink
        if msg.autopilot == M.MAV_AUTOPILOT_INVALID or msg.type == M.MAV_TYPE_GCS:
            return False
        v = self.vehicle
        # Lock onto the first autopilot seen; later ones (a second vehicle, a camera) are
        # someone else's.
        return v.system == 0 or (msg.get_srcSystem(), msg.get_srcComponent()) == (
            v.system, v.component)

    def _note_heartbeat(self, msg: Any, t: float) -> None:
        v = self.vehicle
        v.system, v.component = msg.get_srcSystem(), msg.get_srcComponent()
        v.autopilot_id = msg.autopilot
        v.autopilot = Autopilot.from_heartbeat(msg.autopilot)
        v.mav_type, v.base_mode, v.custom_mode = msg.type, msg.base_mode, msg.custom_mode
        v.system_status = msg.system_status
        v.last_heartbeat = t
        v.heartbeats += 1
        self._conn.target_system, self._conn.target_component = v.system, v.component

    def wait_heartbeat(self, timeout: float, progress: Callable[[str], None] | None = None
                       ) -> VehicleState:
        """Wait up to ``timeout`` s of wall time for the vehicle's first HEARTBEAT.

        Wall time whatever the speedup: this waits for a vehicle (or a simulator process)
        to start. ``progress`` gets a line every 5 s.

        Raises
        ------
        JobFailedError
            None came; the message says what was heard instead (wrongly signed or
            unsigned messages, only other ground stations, nothing at all).
        """
        start = time.monotonic()
        next_note = start + 5.0
        while self.vehicle.last_heartbeat is None:
            now = time.monotonic()
            if now - start >= timeout:
                raise JobFailedError(self._no_heartbeat_reason(timeout))
            if progress is not None and now >= next_note:
                progress(f"waiting for a vehicle heartbeat on {self.connect} "
                         f"({now - start:.0f} s of {timeout:g} s)")
                next_note += 5.0
            self.poll(self.clock.speedup * min(0.1, timeout - (now - start)))
        return self.vehicle

    def _no_heartbeat_reason(self, timeout: float) -> str:
        base = f"no vehicle heartbeat on {self.connect} within {timeout:g} s"
        if self.rejected_signed:
            return (f"{base}: {self.rejected_signed} messages had a wrong signature (is "
                    "--signing-key the vehicle's passphrase?)")
        if self.rejected_unsigned:
            return (f"{base}: {self.rejected_unsigned} unsigned messages were rejected (the "
                    "vehicle does not sign; drop --signing-key?)")
        return base

    def signing_problem(self) -> str | None:
        """A one-line explanation when the vehicle signs and we cannot, else None."""
        if self.unverified_signed and self._conn.mav.signing.secret_key is None:
            return ("the vehicle signs its messages and will ignore ours: pass "
                    "--signing-key with its passphrase")
        return None

    def enum_name(self, enum: str, value: int) -> str:
        """Name of a MAVLink enum value (e.g. ``MAV_RESULT_DENIED``), or the number."""
        entry = self.mavlink.enums.get(enum, {}).get(int(value))
        return entry.name if entry is not None else f"{enum} {value}"
