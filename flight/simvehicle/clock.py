"""Pacing of the simulated vehicle: fixed sim-time ticks locked to the wall clock.

Sim time is tied to the wall clock, ``t_sim = (wall - wall_0) · speedup``, and never to
the number of ticks run: tick ``i`` (sim time ``i · dt``) is due at wall time
``wall_0 + i · dt / speedup``. A loop that falls behind runs the overdue ticks back to
back until it has caught up, so a late tick delays telemetry a little but never shifts
the timeline (no drift). `SimClock` also keeps the lateness statistics reported at exit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

__all__ = ["ClockStats", "SimClock"]

#: Sleep at most this long (wall seconds) at a time, so a stop request is seen promptly.
_MAX_SLEEP = 0.02


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
    """

    ticks: int
    sim_time: float
    wall_time: float
    mean_tick_rate: float
    max_lag: float
    late_ticks: int


class SimClock:
    """Maps ticks of ``dt`` sim seconds onto the wall clock, ``speedup`` times faster.

    Parameters
    ----------
    dt : float
        Tick period, sim seconds.
    speedup : float
        Sim seconds per wall second (> 0).
    """

    def __init__(self, dt: float, speedup: float = 1.0) -> None:
        if not (dt > 0.0 and speedup > 0.0):
            raise ValueError("tick period and speedup must be positive")
        self.dt = float(dt)
        self.speedup = float(speedup)
        self._wall_dt = self.dt / self.speedup
        self._wall0: float | None = None
        self.ticks = 0
        self._max_lag = 0.0
        self._late = 0

    def start(self) -> None:
        """Start the clock: sim time 0 is now."""
        self._wall0 = time.perf_counter()

    @property
    def started(self) -> bool:
        """Whether `start` was called."""
        return self._wall0 is not None

    def now(self) -> float:
        """Sim time according to the wall clock, s (not the last tick's time)."""
        assert self._wall0 is not None, "start() first"
        return (time.perf_counter() - self._wall0) * self.speedup

    @property
    def tick_time(self) -> float:
        """Sim time of the next tick to run, s."""
        return self.ticks * self.dt

    def due(self) -> bool:
        """Whether the next tick is due (its wall time has come); records its lateness."""
        assert self._wall0 is not None, "start() first"
        lag = time.perf_counter() - (self._wall0 + self.ticks * self._wall_dt)
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
        remaining = self._wall0 + self.ticks * self._wall_dt - time.perf_counter()
        if remaining > 0.0:
            time.sleep(min(remaining, _MAX_SLEEP))

    def stats(self) -> ClockStats:
        """Timing statistics so far."""
        wall = 0.0 if self._wall0 is None else time.perf_counter() - self._wall0
        rate = self.ticks / wall / self.speedup if wall > 0.0 else 0.0
        return ClockStats(ticks=self.ticks, sim_time=self.tick_time, wall_time=wall,
                          mean_tick_rate=rate, max_lag=self._max_lag, late_ticks=self._late)
