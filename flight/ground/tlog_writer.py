"""The streamer's clock and its raw MAVLink log (``flight.tlog``).

A ``.tlog`` is the ground-station convention pymavlink and MAVProxy read: records of an
8-byte big-endian timestamp (µs since the Unix epoch) followed by one MAVLink packet as
sent on the wire. `TlogWriter` writes each record with a single unbuffered ``write``, so
the file is complete up to the last packet whenever the process dies.

`LinkClock` is the streamer's time: monotonic seconds since it started, multiplied by the
speedup when flying against a simulator that runs faster than real time. Every time the
streamer handles — trajectory clock, setpoint period, heartbeat period, timeouts — is on
this clock, and the tlog stamps are the start's epoch time plus this clock, so a tlog of
a sped-up flight reads as if flown in real time.
"""

from __future__ import annotations

import struct
import threading
import time
from pathlib import Path

from mavsysid.errors import InputError

__all__ = ["LinkClock", "TlogWriter"]


class LinkClock:
    """Streamer time: monotonic seconds since creation × ``speedup``.

    Parameters
    ----------
    speedup : float
        How many streamer seconds pass per wall second (> 0; 1 for a real vehicle).
    """

    def __init__(self, speedup: float = 1.0) -> None:
        if not speedup > 0.0:
            raise InputError(f"--speedup {speedup:g}: expected a positive factor")
        self.speedup = float(speedup)
        self._mono0 = time.monotonic()
        self._epoch0 = time.time()

    def now(self) -> float:
        """Streamer seconds since the clock started."""
        return (time.monotonic() - self._mono0) * self.speedup

    def wall(self, seconds: float) -> float:
        """Wall-clock seconds that ``seconds`` of streamer time take."""
        return seconds / self.speedup

    def epoch_us(self, t: float | None = None) -> int:
        """The tlog stamp of streamer time ``t`` (now by default): µs since the epoch."""
        return int((self._epoch0 + (self.now() if t is None else t)) * 1e6)

    def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` of streamer time."""
        if seconds > 0.0:
            time.sleep(self.wall(seconds))


class TlogWriter:
    """Appends timestamped raw packets to a new ``.tlog`` (thread-safe).

    Parameters
    ----------
    path : Path
        The file to create (an existing file is an `InputError`: never overwrite a log).
    clock : LinkClock
        Stamps each record with `LinkClock.epoch_us`.
    """

    def __init__(self, path: Path, clock: LinkClock) -> None:
        self.path = Path(path)
        self.clock = clock
        self.records = 0
        self._lock = threading.Lock()
        try:
            # Unbuffered: each record reaches the OS in one write() as it is made.
            self._file = open(self.path, "xb", buffering=0)  # noqa: SIM115 - closed by close()
        except FileExistsError:
            raise InputError(f"{self.path}: exists; refusing to overwrite a flight log") from None

    def write(self, packet: bytes | bytearray) -> None:
        """Record one packet, stamped now."""
        data = bytes(packet)
        with self._lock:
            # Stamped under the lock, so records from the heartbeat thread and the main
            # loop stay in time order in the file.
            if not self._file.closed:
                self._file.write(struct.pack(">Q", self.clock.epoch_us()) + data)
                self.records += 1

    def close(self) -> None:
        """Close the file. Harmless twice."""
        with self._lock:
            self._file.close()
