"""Continuing a streamed flight: more trajectories flown after the first, in the same run.

After the session's trajectory ends in hover, a *continuation* (a caller's callback) is
asked for the next trajectory, given what has been recorded so far (`FlightSoFar`: the
flight directory, whose ``pose.csv`` has every row up to now on disk, and where the
vehicle holds). It may take a while (estimate θ from the recording, plan the rest of the
flight: `mavsysid.pipeline.replanned_stream`), so it runs in a worker thread while this
thread keeps the vehicle holding: the hover setpoint streams, and the same guards watch
as during the trajectory (box and limits on every setpoint, tracking, mode, link loss).

The trajectory returned (`NextSegment`) passes the same pre-flight check as the first
(`mavsysid.flight.ground.preflight.check_plan`: box and vehicle limits) before one setpoint
of it is sent; a refusal, or a continuation that fails, raises `ContinuationStopped` and
the streamer lands. None ends the flight normally (the streamer lands). Each segment is
recorded in ``meta.json`` under ``segments`` (kind, duration, windows on both clocks,
setpoint statistics, the hold while the continuation ran and its wall time, and the
continuation's own record), and ``trajectory_window`` spans the first segment's start to
the last one's end.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.flight.gc_freeze import frozen_collector
from mavsysid.flight.ground.autopilot_limits import (
    continuation_limit_refusals,
    kinematic_limits,
    limits_in_effect,
)
from mavsysid.flight.ground.preflight import check_plan
from mavsysid.flight.ground.setpoints import Setpoint, hold, trajectory_setpoint
from mavsysid.flight.ground.stream_control import ProgressLine
from mavsysid.flight.ground.stream_session import StreamSession
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.kinematic_limits import KinematicLimits
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError, MavsysidError

__all__ = [
    "START_TOLERANCE",
    "Continuation",
    "ContinuationStopped",
    "FlightSoFar",
    "Mover",
    "NextSegment",
    "SegmentRun",
    "combined_statistics",
    "continue_flight",
    "hold_while",
    "stream_segment",
]

#: Farther than this from the hold (m), the next trajectory is reached by a smooth move.
START_TOLERANCE = 0.01
# How long the holding thread waits on the link between looks at the worker, streamer s.
_POLL = 0.05


@dataclass(frozen=True)
class FlightSoFar:
    """What a continuation is given: the recording so far and where the vehicle holds.

    Attributes
    ----------
    directory : Path
        The flight directory (``pose.csv`` holds every row received so far).
    pose : Path
        Its ``pose.csv``.
    config : VehicleConfig
        The vehicle flown (its nominal θ), as the streamer checks against.
    box : tuple of 6 float
        The operator's flight box, m.
    window_start : float or None
        When the first segment's first setpoint went out, s on pose.csv's clock (the
        vehicle's); None if the clock offset was not known yet.
    flown : float
        Trajectory time flown so far, all segments, s.
    hover : tuple of 4 float
        The hold [x, y, z, yaw] (m, rad; ENU, yaw unwrapped as the trajectory had it).
    segments : int
        Segments flown so far.
    autopilot_limits : KinematicLimits or None
        The autopilot's position-controller limits in effect (as read before arming, with
        what ``--set-limits`` raised); a next segment beyond them is refused. None: none
        were read.
    """

    directory: Path
    pose: Path
    config: VehicleConfig
    box: tuple[float, ...]
    window_start: float | None
    flown: float
    hover: tuple[float, float, float, float]
    segments: int
    autopilot_limits: KinematicLimits | None = None


@dataclass(frozen=True)
class NextSegment:
    """A continuation's answer: the trajectory to fly next and what to record about it.

    Attributes
    ----------
    trajectory : PiecewisePolynomial
        From hover to hover; should start at `FlightSoFar.hover` (else a smooth move
        flies there first).
    kind : str
        Recorded as the segment's kind (e.g. ``replanned``).
    record : mapping
        JSON-serialisable facts stored with the segment in meta.json (the estimate used…).
    """

    trajectory: PiecewisePolynomial
    kind: str = "continuation"
    record: Mapping[str, Any] = field(default_factory=dict)


#: Given the flight so far, the next segment, or None to land.
Continuation = Callable[[FlightSoFar], NextSegment | None]
#: Flies a smooth move: (from position, from yaw, to position, to yaw, what) → None.
Mover = Callable[[np.ndarray, float, np.ndarray, float, str], None]


class ContinuationStopped(JobFailedError):
    """The continuation failed or its trajectory was refused: the vehicle must land."""


@dataclass(frozen=True)
class SegmentRun:
    """One streamed trajectory: streamer start and end times (s) and setpoint statistics."""

    start: float
    end: float
    statistics: dict[str, Any]


def stream_segment(session: StreamSession, trajectory: PiecewisePolynomial, progress: bool,
                   say: Callable[[str], None],
                   on_start: Callable[[float], None] | None = None) -> SegmentRun:
    """Stream ``trajectory`` at the setpoint rate until its end, with the progress line.

    ``on_start`` is called with the streamer time of its first setpoint. On return the
    stream still sends the trajectory's last setpoint (set a hold next).
    """
    duration = trajectory.duration
    st = session.settings
    say(f"streaming the {duration:.1f} s trajectory at {st.rate:g} Hz")
    line = ProgressLine(duration, enabled=progress)
    # A collection can stall the stream: pause the collector while streaming. What is
    # alive now is frozen rather than collected: a full collection of a large process
    # (a caller's planner graph, freshly compiled kernels) took 0.9 s, long enough for
    # the socket's receive buffer to overflow and lose a third of a second of telemetry.
    with frozen_collector(pause=True):
        schedule = session.stream.start(lambda t: trajectory_setpoint(trajectory, t))
        if on_start is not None:
            on_start(schedule.start)
        clock, link = session.link.clock, session.link
        last_sent, last_t = 0, schedule.start
        try:
            while (now := clock.now()) < schedule.start + duration:
                link.poll_until(min(schedule.start + duration, now + 0.1 * st.speedup))
                now = clock.now()
                rate = (schedule.sent - last_sent) / max(now - last_t, 1e-9)
                if now - last_t >= 1.0:
                    last_sent, last_t = schedule.sent, now
                latest = session.recorder.latest
                line.update(now - schedule.start, rate,
                            None if latest is None else latest.tracking_error,
                            time.monotonic())
        finally:
            line.close()
    return SegmentRun(schedule.start, clock.now(), schedule.statistics())


def hold_while(session: StreamSession, task: Callable[[], Any]) -> Any:
    """Run ``task`` in a worker thread while this thread keeps the link (and the hold) going.

    Returns what ``task`` returned; raises what it raised. A guard, a lost link or an
    interrupt raised by the link stops the wait (the worker is abandoned: a daemon).
    """
    outcome: dict[str, Any] = {}

    def work() -> None:
        try:
            outcome["value"] = task()
        except BaseException as error:  # handed over to the holding thread
            outcome["error"] = error

    worker = threading.Thread(target=work, name="continuation", daemon=True)
    worker.start()
    while worker.is_alive():
        session.link.poll(_POLL)
    if "error" in outcome:
        raise outcome["error"]
    return outcome.get("value")


def combined_statistics(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """Setpoint statistics of several segments as one: counts summed, rates and mean
    deviations weighted by setpoints sent, p99 and max deviations the largest."""
    out: dict[str, Any] = {key: sum(int(p.get(key, 0)) for p in parts)
                           for key in ("sent", "dropped", "late")}
    out["nominal_rate_hz"] = parts[0].get("nominal_rate_hz")
    timed = [p for p in parts if "rate_hz" in p]
    if timed:
        weight = np.array([p["sent"] for p in timed], dtype=float)
        for key in ("rate_hz", "period_deviation_mean_s"):
            out[key] = float(np.average([p[key] for p in timed], weights=weight))
        for key in ("period_deviation_p99_s", "period_deviation_max_s"):
            out[key] = float(max(p[key] for p in timed))
    return out


def continue_flight(session: StreamSession, end: Setpoint, first: SegmentRun,
                    continuation: Continuation, move: Mover, progress: bool,
                    say: Callable[[str], None]) -> Setpoint:
    """Ask ``continuation`` for segments and fly them, holding in between.

    Parameters
    ----------
    session : StreamSession
        Its first trajectory flown, the hold at ``end`` streaming.
    end : Setpoint
        The hold at the first trajectory's end.
    first : SegmentRun
        How the first trajectory streamed.
    continuation : Continuation
    move : Mover
        Flies a smooth move (the streamer's, with its tracking guard).
    progress : bool
        Show the progress line while a segment streams.
    say : callable

    Returns
    -------
    Setpoint
        The hold at the last segment's end (streaming).

    Raises
    ------
    ContinuationStopped
        The continuation failed or its trajectory was refused; the hold still streams.
    """
    runs = [first]
    records = [_segment_record(session, "opening", session.trajectory.duration, first)]
    flown = session.trajectory.duration
    while True:
        so_far = FlightSoFar(session.directory, session.directory / "pose.csv", session.config,
                             session.box, session.meta.get("trajectory_window", {}).get(
                                 "start"), flown, (*end.position, end.yaw), len(runs),
                             _limits_now(session))
        say("holding while the next segment is prepared")
        held_from, wall = session.link.clock.now(), time.monotonic()
        try:
            nxt = hold_while(session, lambda s=so_far: continuation(s))
        except Exception as error:  # whatever went wrong, the vehicle lands
            why = error if isinstance(error, MavsysidError) else repr(error)
            raise ContinuationStopped(f"the continuation after {flown:.1f} s of flight "
                                      f"failed: {why}") from error
        hold_record = {"hold_s": session.link.clock.now() - held_from,
                       "continuation_wall_s": time.monotonic() - wall}
        if nxt is None:
            session.note("segments", records + [{"kind": "end", **hold_record}])
            say(f"no further segment after {flown:.1f} s of flight")
            return end
        refused = [*check_plan(nxt.trajectory, session.config.name, session.config,
                               session.box, "the flight box").refusals,
                   *_limit_refusals(session, nxt.trajectory)]
        if refused:
            records.append({"kind": nxt.kind, "refused": list(refused), **hold_record,
                            **dict(nxt.record)})
            session.note("segments", records)
            raise ContinuationStopped(f"{nxt.kind} trajectory refused: {'; '.join(refused)}")
        first_sp = trajectory_setpoint(nxt.trajectory, 0.0)
        if np.linalg.norm(np.subtract(first_sp.position, end.position)) > START_TOLERANCE:
            move(np.array(end.position), end.yaw, np.array(first_sp.position), first_sp.yaw,
                 f"flying to the {nxt.kind} trajectory's start")
        run = stream_segment(session, nxt.trajectory, progress, say)
        last = trajectory_setpoint(nxt.trajectory, nxt.trajectory.duration)
        end = hold(np.array(last.position), last.yaw)
        session.stream.start(lambda _t, e=end: e)
        runs.append(run)
        flown += nxt.trajectory.duration
        records.append({**_segment_record(session, nxt.kind, nxt.trajectory.duration, run),
                        **hold_record, **dict(nxt.record)})
        session.note("segments", records)
        session.note_trajectory_end(run.end, combined_statistics([r.statistics for r in runs]))
        session.link.poll(session.settings.hold_time)


def _limits_now(session: StreamSession) -> KinematicLimits | None:
    """The autopilot's tracking limits in effect as SI bounds for the planner (None: none
    were read)."""
    values = limits_in_effect(session.meta.get("autopilot_limits"), session.parameters.changed)
    return None if values is None else kinematic_limits(
        session.link.vehicle.autopilot, values, tracking_only=True)


def _limit_refusals(session: StreamSession, trajectory: PiecewisePolynomial) -> list[str]:
    values = limits_in_effect(session.meta.get("autopilot_limits"), session.parameters.changed)
    return [] if values is None else continuation_limit_refusals(
        session.link.vehicle.autopilot, values, trajectory)


def _segment_record(session: StreamSession, kind: str, duration: float,
                    run: SegmentRun) -> dict[str, Any]:
    return {"kind": kind, "duration": duration,
            "window": {"start": session.vehicle_time(run.start),
                       "end": session.vehicle_time(run.end),
                       "streamer_start": run.start, "streamer_end": run.end},
            "setpoints": run.statistics}
