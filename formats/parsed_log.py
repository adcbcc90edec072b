"""What the autopilot-log readers return: timed series in the log's own frames and numbering.

Each autopilot log format reads into a `ParsedLog` (`mavsysid.formats.tlog.read_tlog`,
`mavsysid.formats.ulog.read_ulog`, `mavsysid.formats.dataflash.read_dataflash`): the pose,
rotor speeds, motor outputs, ESC speeds and IMU the log holds, in SI units (s on the
log's clock, m, rad/s, m/s²) and in the log's own conventions, which are every
autopilot's: world NED, body FRD, and motor outputs in the autopilot's numbering.
Putting them into the project's conventions is the caller's, with the one converter of
each: `mavsysid.vehicle.frames` (NED/FRD → ENU/FLU) and `mavsysid.vehicle.motor_order`
(autopilot motor → config rotor). Cleaning the samples (NaN, order, repeats) is the
caller's too.

Also here: `motor_output_count`, how many of the output slots an autopilot logs (8, 14, 16
of them) drive motors, which every format's reader asks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["ImuFilter", "ModeChanges", "MotorOutputKind", "MotorOutputs", "ParsedLog",
           "PoseSource", "Series", "motor_output_count"]

#: Where a pose came from: motion capture or vision sent to the vehicle, or the
#: autopilot's own estimate.
PoseSource = Literal["motion_capture", "autopilot"]
#: What motor output values are: "pwm", a pulse width in µs (ArduPilot's RCOU, whatever
#: the ESC protocol, MAVLink's SERVO_OUTPUT_RAW, PX4's actuator_outputs of its PWM
#: driver); "normalised", PX4's actuator_motors relative thrust command (0..1, −1..1 for
#: a reversible motor, NaN a stopped motor).
MotorOutputKind = Literal["pwm", "normalised"]


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
class MotorOutputs:
    """The motor outputs of a log as the autopilot sent them, before any motor curve.

    Attributes
    ----------
    series : Series
        One column per output slot that drives a motor (slots 1..m, `motor_output_count`),
        the values as logged (not clipped: a value outside the PWM range stays so).
    kind : {"pwm", "normalised"}
        Their unit (`MotorOutputKind`).
    """

    series: Series
    kind: MotorOutputKind


@dataclass(frozen=True)
class ImuFilter:
    """The software low-pass the logged IMU samples went through, as the log states it.

    Attributes
    ----------
    gyro_cutoff_hz, accel_cutoff_hz : float or None
        Cutoff frequency, Hz, of the low-pass filter applied to the logged gyro and
        accelerometer samples (ArduPilot INS_GYRO_FILTER / INS_ACCEL_FILTER, PX4
        IMU_GYRO_CUTOFF / IMU_ACCEL_CUTOFF); 0.0 when the samples were logged before that
        filter (raw samples); None when the log does not say.
    source : str
        Where the values came from, for messages ("PARM INS_GYRO_FILTER, …").
    """

    gyro_cutoff_hz: float | None
    accel_cutoff_hz: float | None
    source: str


@dataclass(frozen=True)
class ParsedLog:
    """The pose, rotor speeds and IMU of one autopilot log, in the log's own conventions.

    The pose is either one series (``pose``: motion capture or vision, position and
    attitude sampled together) or two separately timed ones (``position`` and
    ``attitude``: the autopilot's estimate), or absent.

    ``rotors`` is the reader's one choice of rotor speeds (measured ESC rpm, else the
    motor outputs through the vehicle's motor curve); ``motor_outputs`` and
    ``esc_speeds`` keep both inputs as logged, so that a caller may check one against
    the other. The IMU (``gyro``, ``accel``) is at its own rate, usually faster than the
    pose.

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
    gyro : Series or None
        m = 3: body rates, rad/s, body FRD, as the primary gyro logs them (the label
        names the message, e.g. "IMU GyrX..Z (I=0)").
    accel : Series or None
        m = 3: specific force, m/s², body FRD, as the primary accelerometer reads it:
        [0, 0, −9.81] level at rest, (F_B/m) in flight (no gravity in it).
    imu_position : tuple of 3 float or None
        The IMU's offset from the centre of gravity, m, body FRD, from the log's
        parameters (ArduPilot INS_POS1_X/Y/Z, PX4 EKF2_IMU_POS_X/Y/Z); None if the log
        does not state it.
    imu_filter : ImuFilter or None
        The low-pass the logged ``gyro`` and ``accel`` went through, where the log says.
    motor_outputs : MotorOutputs or None
        The motor outputs as logged (PWM µs or normalised commands), where the log has
        them.
    esc_speeds : tuple of Series
        Measured ESC rotor speeds, rad/s (rpm × 2π/60), however sparse; their columns,
        concatenated in order, are the autopilot's motors 1..m. Empty without ESC rpm.
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
    gyro: Series | None = None
    accel: Series | None = None
    imu_position: tuple[float, float, float] | None = None
    imu_filter: ImuFilter | None = None
    motor_outputs: MotorOutputs | None = None
    esc_speeds: tuple[Series, ...] = ()


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
