"""A serial cable for the tests: two pseudo-terminals joined like a null-modem cable.

``NullModem`` opens two pseudo-terminal pairs with Python's `pty` and copies every byte
written to one end's device to the other's, in both directions, from a thread of its own:
what ``socat pty,raw,echo=0 pty,raw,echo=0`` does. The vehicle (``mavsysid sim --connect
DEVICE:BAUD``) opens one end, the ground station (``mavsysid stream --connect
DEVICE:BAUD``) the other; both go through pyserial as they would on a USB cable or a
telemetry radio. Both ends are set raw at once (no echo, no line editing), so bytes sent
before the other side has opened its end are neither echoed back nor mangled.

``pause(True)`` stops the copying (both directions) as a radio out of range would; bytes
written meanwhile are dropped, as are bytes for an end whose buffer is full because nobody
reads it (a UART overrun). The baud rate is the devices' setting only: a pseudo-terminal
does not pace the bytes.
"""

from __future__ import annotations

import contextlib
import os
import pty
import select
import threading
import tty

__all__ = ["NullModem"]


class NullModem:
    """Two joined pseudo-terminals (see the module docstring); a context manager.

    Attributes
    ----------
    vehicle, ground : str
        The device paths of the two ends (``/dev/pts/N``).
    copied : int
        Bytes copied so far, both directions.
    """

    def __init__(self) -> None:
        self._master_a, self._slave_a = pty.openpty()
        self._master_b, self._slave_b = pty.openpty()
        for fd in (self._slave_a, self._slave_b):
            tty.setraw(fd)
        for fd in (self._master_a, self._master_b):
            os.set_blocking(fd, False)
        self.vehicle = os.ttyname(self._slave_a)
        self.ground = os.ttyname(self._slave_b)
        self.copied = 0
        self._paused = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._copy, name="null-modem", daemon=True)
        self._thread.start()

    def pause(self, paused: bool) -> None:
        """Stop (True) or resume (False) the copying; bytes sent while paused are lost."""
        if paused:
            self._paused.set()
        else:
            self._paused.clear()

    def _copy(self) -> None:
        other = {self._master_a: self._master_b, self._master_b: self._master_a}
        while not self._stop.is_set():
            ready, _, _ = select.select(list(other), [], [], 0.1)
            for fd in ready:
                try:
                    data = os.read(fd, 65536)
                except OSError:  # nothing after all (non-blocking)
                    continue
                if data and not self._paused.is_set():
                    self.copied += self._write(other[fd], data)

    @staticmethod
    def _write(fd: int, data: bytes) -> int:
        """Write what the other end's buffer takes; the rest is lost (an overrun)."""
        try:
            return os.write(fd, data)
        except OSError:
            return 0

    def close(self) -> None:
        """Stop the copying and close both pseudo-terminals."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self._master_a, self._slave_a, self._master_b, self._slave_b):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> NullModem:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
