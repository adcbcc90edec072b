"""The streamer's clock, which also stamps its raw MAVLink log (``flight.tlog``).

`LinkClock` is the streamer's time: monotonic seconds since it started, multiplied by the
speedup when flying against a simulator that runs faster than real time. Every time the
streamer handles — trajectory clock, setpoint period, heartbeat period, timeouts — is on
this clock, and the tlog stamps (`mavsysid.formats.tlog.TlogWriter`) are the start's
epoch time plus this clock, so a tlog of a sped-up flight reads as if flown in real time.

With ``lockstep`` (a test and bench tool, against ``mavsysid sim --lockstep`` only; see
`mavsysid.flight.simvehicle.clock`), the clock *is* the vehicle's sim time: it stands at 0
until the first lock-step frame (a SYSTEM_TIME whose unix time equals its boot time), then
reads the time of the last frame, computed from that frame's milliseconds alone, so that
every time the streamer compares (a setpoint due, a timeout) is the same number, to the
last bit, in every run of the same flight (`received` stamps a message no earlier than
the vehicle sent it). It tells the link which frame to acknowledge
(`take_ack`) when it is about to wait. Should the frames stop (a lost or killed vehicle)
for `FRAME_GRACE` wall seconds, it goes on with the wall clock, so timeouts still expire,
and never runs backwards when frames come back (it then keeps an offset from the
vehicle's time). Before the first frame it waits `FRAME_GRACE` after the first message
(a vehicle that sends no frames: a real autopilot, the wall clock then runs) and
`START_GRACE` while nothing at all came (a simulator still starting on a loaded machine;
no vehicle at all).
"""

from __future__ import annotations

import time
from typing import Any

from mavsysid.flight.mavlink_setup import GCS_SYSTEM

from mavsysid.errors import InputError

__all__ = ["FRAME_GRACE", "FRAME_WAIT", "START_GRACE", "LinkClock"]

#: Wall seconds without a lock-step frame after which the clock runs on the wall clock.
FRAME_GRACE = 2.0
#: Wall seconds a lock-step clock stands at 0 while no message at all has come: a
#: simulator that compiles its kernels first (a changed source) on a loaded machine takes
#: tens of seconds. Waits on the streamer clock (the wait for a heartbeat polls on it)
#: end no earlier.
START_GRACE = 60.0
#: Shortest wall wait while following lock-step frames, s.
FRAME_WAIT = 0.01


class LinkClock:
    """Streamer time: monotonic seconds since creation × ``speedup``.

    Parameters
    ----------
    speedup : float
        How many streamer seconds pass per wall second (> 0; 1 for a real vehicle).
    lockstep : bool
        Follow the vehicle's lock-step frames (see the module docstring).

    Attributes
    ----------
    frames : int
        Lock-step frames followed.
    """

    def __init__(self, speedup: float = 1.0, lockstep: bool = False) -> None:
        if not speedup > 0.0:
            raise InputError(f"--speedup {speedup:g}: expected a positive factor")
        self.speedup = float(speedup)
        self.lockstep = lockstep
        self.frames = 0
        self._mono0 = time.monotonic()
        self._epoch0 = time.time()
        self._frame_ms: int | None = None  # vehicle time of the last frame
        self._frame_now = 0.0  # streamer time at the last frame
        self._behind = 0.0  # vehicle time behind streamer time, s (0 unless frames stopped)
        self._frame_mono = 0.0  # wall time of the last frame
        self._heard_mono: float | None = None  # wall time of the first message
        self._ack_ms: int | None = None

    def now(self) -> float:
        """Streamer seconds since the clock started."""
        mono = time.monotonic()
        if self._frame_ms is None:
            if not self.lockstep:
                return (mono - self._mono0) * self.speedup
            # Lock-step: still until the first frame, as the held vehicle is.
            runs_from = self._mono0 + START_GRACE
            if self._heard_mono is not None:
                runs_from = min(runs_from, self._heard_mono + FRAME_GRACE)
            return max(mono - runs_from, 0.0) * self.speedup
        stalled = mono - self._frame_mono - FRAME_GRACE
        return self._frame_now + (stalled * self.speedup if stalled > 0.0 else 0.0)

    def observe(self, msg: Any) -> None:
        """Follow a lock-step frame from the vehicle (any other message: nothing but
        noting that the vehicle speaks)."""
        if not self.lockstep:
            return
        if self._heard_mono is None:
            self._heard_mono = time.monotonic()
        if msg.get_type() != "SYSTEM_TIME":
            return
        ms = msg.time_boot_ms
        if ms <= 0 or msg.time_unix_usec != ms * 1000:
            return
        if self._frame_ms is not None and ms < self._frame_ms:
            return  # a frame repeated late: time never runs backwards
        now, t = self.now(), ms / 1000 + self._behind
        if t < now:
            # The wall clock stood in for missing frames: never backwards, from now on an
            # offset.
            self._behind, t = self._behind + (now - t), now
        self._frame_ms, self._frame_now, self._frame_mono = ms, t, time.monotonic()
        self._ack_ms = ms
        self.frames += 1

    def received(self, msg: Any) -> float:
        """The receipt time of ``msg`` (just observed), streamer s: now; while following
        lock-step frames, no earlier than the vehicle's stamp (``time_boot_ms``).

        A frame comes after the messages of the ticks it closes, so they arrive while the
        clock still reads the previous frame, up to a frame period before their own time;
        over a real link a message is received after it was sent. `now` (the schedule,
        the timeouts) moves with the frames only, so that what the streamer does is the
        same in every run; this stamp is for recording what came when.
        """
        now = self.now()
        ms = getattr(msg, "time_boot_ms", None)
        if (self._frame_ms is None or ms is None or msg.get_srcSystem() == GCS_SYSTEM
                or time.monotonic() - self._frame_mono >= FRAME_GRACE):
            return now
        return max(now, ms / 1000 + self._behind)

    def take_ack(self) -> int | None:
        """The frame (vehicle ms) to acknowledge now, once; None when nothing is due."""
        ack, self._ack_ms = self._ack_ms, None
        return ack

    def wall(self, seconds: float) -> float:
        """Wall-clock seconds that ``seconds`` of streamer time take.

        While following lock-step frames, at least `FRAME_WAIT`: time moves only when a
        frame comes (which ends any wait on the link), so spinning would only take the
        processor from the vehicle.
        """
        if self._frame_ms is not None and time.monotonic() - self._frame_mono < FRAME_GRACE:
            return max(seconds / self.speedup, FRAME_WAIT)
        return seconds / self.speedup

    def epoch_us(self, t: float | None = None) -> int:
        """The tlog stamp of streamer time ``t`` (now by default): µs since the epoch."""
        return int((self._epoch0 + (self.now() if t is None else t)) * 1e6)

    def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` of streamer time."""
        if seconds > 0.0:
            time.sleep(self.wall(seconds))
