"""What the autopilot-log readers return: timed series in the log's own frames and numbering.

Each autopilot log format reads into a `ParsedLog` (`mavsysid.formats.tlog.read_tlog`,
`mavsysid.formats.ulog.read_ulog`, `mavsysid.formats.dataflash.read_dataflash`): the pose
and rotor speeds the log holds, in SI units (s on the log's clock, m, rad/s) and in the
log's own conventions, which are every autopilot's: world NED, body FRD, and motor outputs
in the autopilot's numbering. Putting them into the project's conventions is the
caller's, with the one converter of each: `mavsysid.vehicle.frames` (NED/FRD → ENU/FLU)
and `mavsysid.vehicle.motor_order` (autopilot motor → config rotor). Cleaning the samples
(NaN, order, repeats) is the caller's too.

Also here: `motor_output_count`, how many of the output slots an autopilot logs (8, 14, 16
of them) drive motors, which every format's reader asks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["ModeChanges", "ParsedLog", "PoseSource", "Series", "motor_output_count"]

#: Where a pose came from: motion capture or vision sent to the vehicle, or the
#: autopilot's own estimate.
PoseSource = Literal["motion_capture", "autopilot"]


@dataclass(frozen=True)
class Series:
    """Timed samples of one signal.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s, on the log's clock (need not be sorted or clean yet).
    values : ndarray, shape (N, m)
        The samples, in the units and frame the reader documents (a pose has m = 7:
        position, m, then the attitude quaternion [w, x, y, z]; rotor speeds have one
        column per motor output, rad/s).
    label : str
        What the samples are, for messages ("ESC_TELEMETRY_1_TO_4 rpm", …).
    """

    t: np.ndarray
    values: np.ndarray
    label: str


@dataclass(frozen=True)
class ModeChanges:
    """The autopilot's flight modes over a log.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s, on the log's clock, increasing.
    modes : tuple of str
        The mode at each sample, as the autopilot names it ("GUIDED", "OFFBOARD", …).
    events : bool
        Each sample is a mode change that holds until the next sample (``MODE``,
        ``vehicle_status``); else the samples are periodic reports (``HEARTBEAT``).
    end : float
        s, where the last mode ends (inf: at the end of the log, not known here).
    """

    t: np.ndarray
    modes: tuple[str, ...]
    events: bool
    end: float


@dataclass(frozen=True)
class ParsedLog:
    """The pose and rotor speeds of one autopilot log, in the log's own conventions.

    The pose is either one series (``pose``: motion capture or vision, position and
    attitude sampled together) or two separately timed ones (``position`` and
    ``attitude``: the autopilot's estimate), or absent.

    Attributes
    ----------
    source : str
        The file.
    pose : Series or None
        m = 7: x, y, z (m, world NED), qw, qx, qy, qz (body FRD → world NED).
    position : Series or None
        m = 3: x, y, z, m, world NED (with ``attitude``; ``pose`` is then None).
    attitude : Series or None
        m = 4: [w, x, y, z], body FRD → world NED.
    pose_source : {"motion_capture", "autopilot"}
    pose_hint : str
        The pose messages the reader looked for, for the error when there is none.
    rotors : tuple of Series
        Rotor speeds, rad/s; their columns, concatenated in order, are the autopilot's
        motor outputs 1..m.
    notes : tuple of str
        Notes from reading the file, one line each.
    rotor_notes : tuple of str
        How the rotor speeds were obtained, when not measured (one line each).
    modes : ModeChanges or None
        The flight modes, where the reader found them in the same pass.
    """

    source: str
    pose: Series | None
    position: Series | None
    attitude: Series | None
    pose_source: PoseSource
    pose_hint: str
    rotors: tuple[Series, ...]
    notes: tuple[str, ...] = ()
    rotor_notes: tuple[str, ...] = ()
    modes: ModeChanges | None = None


def motor_output_count(values: np.ndarray) -> int:
    """How many leading output slots drive motors.

    A motor output moves in flight; an unused slot, or a servo held still, sits at one
    value (0, NaN, its trim or the disarmed PWM) throughout. So the count is the leading
    slots that take more than one value; in a log where nothing moves (the vehicle never
    armed) it is the leading slots that are ever non-zero, as motors idle at a PWM > 0.

    Parameters
    ----------
    values : ndarray, shape (N, m)
        The slots' samples (PWM, thrust or rpm), NaN where a slot is unused.

    Returns
    -------
    int
        The number of leading slots taken as motor outputs, 0 to m.
    """
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return 0
    finite = np.isfinite(values)
    low = np.where(finite, values, np.inf).min(axis=0)
    high = np.where(finite, values, -np.inf).max(axis=0)
    # A slot NaN at times and a number at others moves too (PX4: NaN is a stopped motor).
    moving = (high > low) | (finite.any(axis=0) & ~finite.all(axis=0))
    if not moving.any():
        moving = (finite & (values != 0.0)).any(axis=0)
    return int(np.argmin(moving)) if not moving.all() else values.shape[1]
