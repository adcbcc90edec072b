"""Which log of a flight directory to estimate from, and why.

A flight recorded by `mavsysid stream` or `experiment` holds the ground station's
``flight.tlog`` and, downloaded after landing, the autopilot's own log (``meta.json``
``files.autopilot_log``). Both carry the pose, the IMU and the rotor speeds, at different
rates: ArduCopter logs its motor outputs (RCOU) at 10 Hz where the tlog streams them at 50
Hz; a PX4 ULog holds ESC rpm the link never carried. The estimate answers from the rotor
speeds, so the log whose rotor speeds say most is taken: measured rpm at
``RPM_USABLE_RATE`` or faster before commanded speeds, then the faster series. The choice
and its reason are said in a note; ``pose.csv`` is read only when the directory has no log.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from mavsysid.estimation.readers.samples import LogStreams
from mavsysid.formats.flight_dir import read_meta
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import InputError, LogFormatError

__all__ = ["RPM_USABLE_RATE", "choose_flight_log", "rotor_rate"]

#: Measured rotor speeds at this rate or faster, Hz, beat commanded ones at any rate.
RPM_USABLE_RATE = 10.0
#: Labels of rotor-speed series that are commands through the motor curve, not measured.
_COMMANDED = ("PWM", "actuator_motors")

Reader = Callable[[Path, VehicleConfig], LogStreams]


def rotor_rate(streams: LogStreams) -> tuple[float, bool]:
    """The rotor speeds' median sample rate, Hz, and whether they are measured rpm.

    Parameters
    ----------
    streams : LogStreams
        A log as read; its first rotor series is judged.
    """
    series = streams.rotors[0]
    steps = np.diff(np.asarray(series.t, float))
    steps = steps[steps > 0.0]
    rate = 1.0 / float(np.median(steps)) if steps.size else 0.0
    return rate, not any(word in series.label for word in _COMMANDED)


def _candidates(directory: Path, readers: dict[str, Reader]) -> list[Path]:
    """The directory's logs: those ``meta.json`` names, else every readable log file."""
    meta = directory / "meta.json"
    files = read_meta(meta).get("files", {}) if meta.is_file() else {}
    named = [directory / str(files[key]) for key in ("tlog", "autopilot_log")
             if isinstance(files, dict) and isinstance(files.get(key), str)]
    found = [p for p in named if p.is_file()] or sorted(
        p for p in directory.iterdir()
        if p.is_file() and p.suffix.lower() in readers and p.suffix.lower() != ".csv")
    return found or [p for p in (directory / "pose.csv",) if p.is_file()]


def choose_flight_log(directory: Path, vehicle: VehicleConfig, readers: dict[str, Reader]
                      ) -> tuple[Path, LogStreams, str]:
    """The log of ``directory`` to estimate from (module docstring), read.

    Parameters
    ----------
    directory : Path
        A flight directory (``logs/<flight>/``).
    vehicle : VehicleConfig
        The vehicle, for the readers.
    readers : dict
        The reader of each extension (`mavsysid.estimation.readers.READERS`).

    Returns
    -------
    path : Path
        The chosen log.
    streams : LogStreams
        It, as read.
    note : str
        What was chosen, over what, and why.

    Raises
    ------
    InputError
        A directory with no log.
    LogFormatError
        No log of the directory can be read: the first one's reason.
    """
    candidates = _candidates(directory, readers)
    if not candidates:
        raise InputError(f"{directory}: a flight directory with no flight log "
                         "(flight.tlog, an autopilot log or pose.csv)")
    read: list[tuple[Path, LogStreams, float, bool]] = []
    failed: list[tuple[Path, LogFormatError]] = []
    for path in candidates:
        try:
            streams = readers[path.suffix.lower()](path, vehicle)
        except LogFormatError as error:
            failed.append((path, error))
            continue
        read.append((path, streams, *rotor_rate(streams)))
    if not read:
        raise failed[0][1]
    path, streams, rate, measured = max(
        read, key=lambda c: (c[3] and c[2] >= RPM_USABLE_RATE, c[2]))
    others = [f"{p.name} {r:.3g} Hz" for p, _, r, _ in read if p != path]
    others += [f"{p.name} unreadable ({str(e).split(': ', 1)[-1][:80]})" for p, e in failed]
    what = "measured rpm" if measured else "commanded"
    note = (f"info: {directory}: estimating from {path.name}: its rotor speeds ({what}) at "
            f"{rate:.3g} Hz" + (f", against {', '.join(others)}" if others else ""))
    return path, streams, note
