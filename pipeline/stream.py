"""One ground-station flight: open the session for a trajectory file (plan checks, flight
directory, connection), fly it and return where it was recorded.

`run_stream` is what ``mavsysid stream`` and the demo call; tests call it directly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mavsysid.flight.ground.continuation import Continuation
from mavsysid.flight.ground.stream_session import StreamSession, StreamSettings, open_session
from mavsysid.flight.ground.streamer import fly

__all__ = ["StreamOutcome", "run_stream"]


@dataclass(frozen=True)
class StreamOutcome:
    """A finished flight: its directory and the final metadata (``meta.json``)."""

    directory: Path
    meta: dict[str, Any]


def run_stream(trajectory: str | Path, settings: StreamSettings,
               vehicle: str | Path | None = None, say: Callable[[str], None] | None = None,
               progress: bool = True, at_end: Callable[[StreamSession], None] | None = None,
               continuation: Continuation | None = None) -> StreamOutcome:
    """Fly ``trajectory`` with ``settings`` (see `flight.ground.streamer.fly`, also for ``at_end``
    and ``continuation``).

    Parameters
    ----------
    trajectory : str or Path
        Trajectory file (`mavsysid.formats.trajectory_file`).
    settings : StreamSettings
        Connection, rates, guards and where the flight directory goes.
    vehicle : str or Path, optional
        Shipped vehicle name or TOML path; the configuration stored in the file by default.
    say : callable, optional
        Receives one-line status messages.
    progress : bool
        Show a progress bar while streaming.
    at_end : callable, optional
        Called with the session after the flight.
    continuation : callable, optional
        Further trajectories flown in the same run (`mavsysid.flight.ground.continuation`).

    Raises
    ------
    InputError
        Bad trajectory, vehicle, box or connection string.
    JobFailedError
        Refused or aborted; the flight directory keeps what was recorded.
    KeyboardInterrupt
        After the safe action.
    """
    say = say or (lambda _text: None)
    with open_session(trajectory, settings, vehicle) as session:
        session.commands.say = say
        say(f"recording into {session.directory}")
        fly(session, say, progress, at_end, continuation)
    return StreamOutcome(session.directory, session.meta)
