"""Pacing of the simulated vehicle: fixed sim-time ticks locked to the wall clock.

Sim time is tied to the wall clock, ``t_sim = (wall - wall_0) · speedup``, and never to
the number of ticks run: tick ``i`` (sim time ``i · dt``) is due at wall time
``wall_0 + i · dt / speedup``. A loop that falls behind runs the overdue ticks back to
back until it has caught up, so a late tick delays telemetry a little but never shifts
the timeline (no drift). `SimClock` also keeps the lateness statistics reported at exit.

**Lock-step** (opt-in, a test and bench tool, as ArduPilot's SITL lock-steps its physics
with its simulator): every `LOCKSTEP_FRAME_US` of sim time the vehicle sends a *frame*, a
SYSTEM_TIME whose ``time_unix_usec`` equals its ``time_boot_ms`` × 1000 (no real autopilot
sends that). A lock-step ground station takes its clock from the frames and, when it has
handled everything up to a frame and is about to wait, sends the same kind of SYSTEM_TIME
back: the *acknowledgement*. Once a first acknowledgement came, no tick after a frame runs
before that frame is acknowledged, so both sides see the same sim time however busy the
machine is; the wall clock (× speedup) stays an upper bound on the pace.

A lock-step vehicle also *starts* held: it stops at its first frame (sim time
`LOCKSTEP_FRAME_US`) and sends that frame again every `LOCKSTEP_RESEND` wall seconds until
it is acknowledged, so its timeline does not depend on when the ground station connected
(a UDP peer that binds late, a TCP peer that connects late, a loaded machine). A peer that
is not lock-step aware (MAVProxy, MAVSDK) never acknowledges: `LOCKSTEP_TIMEOUT` wall
seconds after the first message heard from a peer the vehicle gives up waiting and runs on
the wall clock. Likewise a frame unacknowledged for `LOCKSTEP_TIMEOUT` wall seconds (the
ground station died or went idle) returns the vehicle to the wall clock until the next
acknowledgement.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["LOCKSTEP_FRAME_US", "LOCKSTEP_RESEND", "LOCKSTEP_TIMEOUT", "ClockStats",
           "SimClock", "is_lockstep_stamp"]

#: Sleep at most this long (wall seconds) at a time, so a stop request is seen promptly.
_MAX_SLEEP = 0.02
#: Sim time between two lock-step frames, µs (5 control ticks; half a 50 Hz period).
LOCKSTEP_FRAME_US = 10_000
#: Wall seconds a frame may wait for its acknowledgement before the wall clock takes over.
LOCKSTEP_TIMEOUT = 2.0
#: Wall seconds between repeats of a frame that waits for its acknowledgement (a datagram
#: sent before the peer listened is lost).
LOCKSTEP_RESEND = 0.25


def is_lockstep_stamp(msg) -> bool:
    """Whether a SYSTEM_TIME message is a lock-step frame or acknowledgement (see above)."""
    return (msg.get_type() == "SYSTEM_TIME" and msg.time_boot_ms > 0
            and msg.time_unix_usec == msg.time_boot_ms * 1000)


@dataclass(frozen=True)
class ClockStats:
    """Timing of the ticks run so far.

    Attributes
    ----------
    ticks : int
        Ticks run.
    sim_time : float
        Sim time reached, s (``ticks · dt``).
    wall_time : float
        Wall time since start, s.
    mean_tick_rate : float
        Ticks per wall second, divided by the speedup: the nominal tick rate when the
        loop keeps up.
    max_lag : float
        Largest lateness of a tick behind its due wall time, s (wall).
    late_ticks : int
        Ticks run more than one tick period (wall) after they were due.
    lockstep_frames : int
        Lock-step frames acknowledged (0 without lock-step).
    lockstep_timeouts : int
        Frames given up on after `LOCKSTEP_TIMEOUT` (back to the wall clock).
    """

    ticks: int
    sim_time: float
    wall_time: float
    mean_tick_rate: float
    max_lag: float
    late_ticks: int
    lockstep_frames: int = 0
    lockstep_timeouts: int = 0


class SimClock:
    """Maps ticks of ``dt`` sim seconds onto the wall clock, ``speedup`` times faster.

    Parameters
    ----------
    dt : float
        Tick period, sim seconds.
    speedup : float
        Sim seconds per wall second (> 0); with lock-step, the fastest pace.
    lockstep : bool
        Send frames (`frame_due`) and hold ticks for their acknowledgement (from the start;
        see the module docstring).
    wall : callable, optional
        The wall clock, s (default `time.perf_counter`; a test passes a simulated one).
    sleep : callable, optional
        Sleeps for a number of wall seconds on that clock (default `time.sleep`).
    """

    def __init__(self, dt: float, speedup: float = 1.0, lockstep: bool = False,
                 wall: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if not (dt > 0.0 and speedup > 0.0):
            raise ValueError("tick period and speedup must be positive")
        self._wall, self._sleep = wall, sleep
        self.dt = float(dt)
        self.speedup = float(speedup)
        self._wall_dt = self.dt / self.speedup
        self._wall0: float | None = None
        self.ticks = 0
        self._max_lag = 0.0
        self._late = 0
        self.lockstep = lockstep
        self.engaged = False  # an acknowledgement came, and no frame timed out since
        self._frame_us: int | None = None  # the last frame sent, awaiting its ack
        self._frame_wall = self._resent_wall = 0.0
        self._peer_wall: float | None = None  # when a peer was first heard
        self._gave_up_start = False  # a peer that never acknowledges: the wall clock
        self._acked_us = -1
        self._acks = self._timeouts = 0
        self._held = False
        self._started = 0.0

    def start(self) -> None:
        """Start the clock: sim time 0 is now."""
        self._wall0 = self._started = self._wall()

    @property
    def started(self) -> bool:
        """Whether `start` was called."""
        return self._wall0 is not None

    def now(self) -> float:
        """Sim time according to the wall clock, s (not the last tick's time)."""
        assert self._wall0 is not None, "start() first"
        return (self._wall() - self._wall0) * self.speedup

    @property
    def tick_time(self) -> float:
        """Sim time of the next tick to run, s."""
        return self.ticks * self.dt

    # --- lock-step ------------------------------------------------------------------------
    def frame_due(self, t_us: int) -> bool:
        """Whether a lock-step frame is to be sent at sim time ``t_us``."""
        return self.lockstep and t_us > 0 and t_us % LOCKSTEP_FRAME_US == 0

    def frame_sent(self, t_us: int) -> None:
        """Note the frame of sim time ``t_us`` as sent (later ticks wait for its ack)."""
        self._frame_us = t_us
        self._frame_wall = self._resent_wall = self._wall()

    def resend_due(self) -> int | None:
        """The held frame (sim µs) to send again now, once per `LOCKSTEP_RESEND`; or None."""
        if self._frame_us is None or self._acked_us >= self._frame_us:
            return None
        now = self._wall()
        if now - self._resent_wall < LOCKSTEP_RESEND:
            return None
        self._resent_wall = now
        return self._frame_us

    def heard_peer(self) -> None:
        """A message came from a peer (starts the time-out of the held start)."""
        if self._peer_wall is None:
            self._peer_wall = self._wall()

    @property
    def starting(self) -> bool:
        """Lock-step, never acknowledged, not given up: waiting for the first ack."""
        return self.lockstep and self._acks == 0 and not self._gave_up_start

    def acknowledge(self, t_us: int) -> None:
        """The ground station has handled everything up to sim time ``t_us``."""
        if not self.lockstep or t_us <= self._acked_us:
            return
        self._acked_us = t_us
        self._acks += 1
        self.engaged = True

    @property
    def held(self) -> bool:
        """Whether the next tick waits for a frame's acknowledgement (times out here)."""
        if self._frame_us is None or self._acked_us >= self._frame_us:
            return False
        if self.engaged:
            since = self._frame_wall
        elif self.starting:
            if self._peer_wall is None:
                return True  # nobody there yet: wait as long as it takes
            since = max(self._frame_wall, self._peer_wall)
        else:
            return False
        if self._wall() - since > LOCKSTEP_TIMEOUT:
            # The peer went away, or never was lock-step aware: the wall clock until an
            # acknowledgement comes.
            self.engaged = False
            self._gave_up_start = True
            self._timeouts += 1
            return False
        return True

    def due(self) -> bool:
        """Whether the next tick is due (its wall time has come); records its lateness."""
        assert self._wall0 is not None, "start() first"
        if self.held:
            self._held = True
            return False
        if self._held:
            # Resume from now: waiting for the peer is not lateness, and catching up in a
            # burst would run sim time faster than speedup × wall.
            self._held = False
            self._wall0 = max(self._wall0,
                              self._wall() - self.ticks * self._wall_dt)
        lag = self._wall() - (self._wall0 + self.ticks * self._wall_dt)
        if lag < 0.0:
            return False
        if lag > self._max_lag:
            self._max_lag = lag
        if lag > self._wall_dt:
            self._late += 1
        return True

    def advance(self) -> None:
        """Count the tick just run."""
        self.ticks += 1

    def sleep_until_due(self) -> None:
        """Sleep until the next tick is due (at most a short slice, to stay responsive)."""
        assert self._wall0 is not None, "start() first"
        remaining = self._wall0 + self.ticks * self._wall_dt - self._wall()
        if remaining > 0.0:
            self._sleep(min(remaining, _MAX_SLEEP))

    def stats(self) -> ClockStats:
        """Timing statistics so far."""
        wall = 0.0 if self._wall0 is None else self._wall() - self._started
        rate = self.ticks / wall / self.speedup if wall > 0.0 else 0.0
        return ClockStats(ticks=self.ticks, sim_time=self.tick_time, wall_time=wall,
                          mean_tick_rate=rate, max_lag=self._max_lag, late_ticks=self._late,
                          lockstep_frames=self._acks, lockstep_timeouts=self._timeouts)
