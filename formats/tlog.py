"""MAVLink telemetry logs (``.tlog``): the record format, the messages read, writer and reader.

A ``.tlog`` is the ground-station convention pymavlink and MAVProxy read: records of an
8-byte big-endian timestamp (µs since the Unix epoch, the receipt time) followed by one
MAVLink packet as sent on the wire. `TlogWriter` writes each record with a single
unbuffered ``write``, so the file is complete up to the last packet whenever the process
dies; `read_tlog` reads a log with pymavlink.

Messages read (MAVLink common and ardupilotmega dialects):

- Pose: ATT_POS_MOCAP (motion capture forwarded to the vehicle; x, y, z NED, q [w, x, y,
  z] FRD → NED) if present, else LOCAL_POSITION_NED with ATTITUDE_QUATERNION (or
  ATTITUDE Euler angles), the autopilot's own estimate.
- Rotor speeds: ESC_TELEMETRY_1_TO_4 / _5_TO_8 / _9_TO_12 ``rpm`` (`ESC_TELEMETRY`: ESC i
  is motor output i + 1), else the SERVO_OUTPUT_RAW port 0 channels that move (the
  motors), PWM through the motor curve (a note says so).
- Modes: the autopilot's HEARTBEAT custom mode, named by pymavlink.
- IMU (body FRD; gyro rad/s, accelerometer specific force: z ≈ −g level at rest), of the
  primary IMU, the first present of: HIGHRES_IMU (``id`` 0; SI floats at ``time_usec``,
  PX4 sends it; rows whose ``fields_updated`` does not flag the sensor are skipped),
  SCALED_IMU (mG and mrad/s at ``time_boot_ms``), RAW_IMU (``id`` 0) of an ArduPilot
  autopilot, which fills it with the same mG and mrad/s of its first IMU
  (``GCS_MAVLINK::send_raw_imu``; another autopilot's RAW_IMU holds raw sensor counts
  and is not read), SCALED_IMU2 / SCALED_IMU3 (the second and third IMU, a note says
  so); the gyro, failing all of those, from ATTITUDE ``rollspeed, pitchspeed,
  yawspeed`` (the AHRS body rates). mG is 1e-3 × `STANDARD_GRAVITY`. The IMU's position
  and filter are the autopilot's parameters where the tlog holds their PARAM_VALUE
  (ArduPilot INS_POS1_X/Y/Z and INS_GYRO_FILTER / INS_ACCEL_FILTER, which ArduPilot's
  IMU messages and ATTITUDE rates went through; PX4 EKF2_IMU_POS_X/Y/Z).

Time base: the autopilot's clock (s since boot), because the pose messages carry it
(``time_boot_ms``), as do the IMU messages (``time_boot_ms``, or ``time_usec`` since
boot; a ``time_usec`` after the year 2001 is a Unix time and is replaced by the receipt
time mapped as below). ESC_TELEMETRY and ATT_POS_MOCAP carry no autopilot time (the mocap
``time_usec`` is the sender's clock), so they are stamped with the tlog's receipt time
mapped onto the autopilot clock: receipt − time_boot_ms over all autopilot messages
with a ``time_boot_ms`` is the clock offset plus that message's link latency, and its
minimum (the fastest message) within each `LAG_WINDOW` of receipt time is taken as the
offset there (so a clock that stops, as a lock-stepped simulator's
does while it waits for its peer, or drifts, is followed). Stamps mapped so are late by
their own latency minus the smallest one, typically a few ms on a direct link.
SERVO_OUTPUT_RAW carries the autopilot's ``time_usec``, used as is (and in the offset
estimate). Without any autopilot time the receipt times are
used, from the first message.

Only messages from the autopilot (the sender of the first HEARTBEAT from an autopilot)
count as the vehicle's, except ATT_POS_MOCAP, which a ground station or companion sends.
"""

from __future__ import annotations

import struct
import threading
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import numpy as np
from mavsysid.formats.bounded_parse import import_parser, parsing
from mavsysid.formats.motor_curve import commanded_rotor_speeds
from mavsysid.formats.parsed_log import (
    ImuFilter,
    ModeChanges,
    MotorOutputs,
    ParsedLog,
    PoseSource,
    Series,
    motor_output_count,
)
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import euler_ned_to_quaternion

from mavsysid.errors import InputError, LogFormatError

__all__ = ["ESC_TELEMETRY", "IMU_MESSAGES", "STANDARD_GRAVITY", "EpochClock", "TlogWriter",
           "read_tlog"]

#: ESC telemetry messages → the motor output (0-based) of their first ``rpm`` entry; each
#: carries four.
ESC_TELEMETRY: dict[str, int] = {"ESC_TELEMETRY_1_TO_4": 0, "ESC_TELEMETRY_5_TO_8": 4,
                                 "ESC_TELEMETRY_9_TO_12": 8}
_CLOCKED = ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "ATTITUDE", "SYSTEM_TIME",
            "GLOBAL_POSITION_INT")
#: The IMU messages read, the primary IMU's first (module docstring).
IMU_MESSAGES = ("HIGHRES_IMU", "SCALED_IMU", "RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")
#: m/s² per G of the mG unit of SCALED_IMU* and RAW_IMU (ArduPilot's GRAVITY_MSS, PX4's
#: CONSTANTS_ONE_G).
STANDARD_GRAVITY = 9.80665
_TYPES = ["HEARTBEAT", "ATT_POS_MOCAP", "SERVO_OUTPUT_RAW", "PARAM_VALUE", "SYS_STATUS",
          *_CLOCKED,
          *ESC_TELEMETRY, *IMU_MESSAGES]
#: HIGHRES_IMU.fields_updated bits of the accelerometer (x, y, z) and the gyro.
_HIGHRES_ACCEL, _HIGHRES_GYRO = 0b000111, 0b111000
#: A time_usec beyond this (µs, 2001) is a Unix time, not time since boot.
_EPOCH_USEC = 1e15
_POSE_HINT = "no ATT_POS_MOCAP, nor LOCAL_POSITION_NED with ATTITUDE_QUATERNION or ATTITUDE"

# (receipt time s, (system, component), message) per message type.
_Messages = dict[str, list[tuple[float, tuple[int, int], Any]]]
# pose (m = 7) or position and attitude, and where the pose comes from.
_Pose = tuple[Series | None, Series | None, Series | None, PoseSource]


class EpochClock(Protocol):
    """What stamps tlog records: `epoch_us` gives the time now, µs since the Unix epoch."""

    def epoch_us(self) -> int:
        """The stamp of a record written now, µs since the Unix epoch."""
        ...


# --- writing -----------------------------------------------------------------------------


class TlogWriter:
    """Appends timestamped raw packets to a new ``.tlog`` (thread-safe).

    Parameters
    ----------
    path : Path
        The file to create (an existing file is an `InputError`: never overwrite a log).
    clock : EpochClock
        Stamps each record with its ``epoch_us()`` (the streamer's
        `mavsysid.flight.ground.link_clock.LinkClock`).
    """

    def __init__(self, path: Path, clock: EpochClock) -> None:
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
        """Record one packet, stamped now.

        Parameters
        ----------
        packet : bytes
            One MAVLink packet as sent or received.
        """
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


# --- reading -----------------------------------------------------------------------------


def _collect(path: Path) -> _Messages:
    """All messages of the types used here, by type."""
    mavutil = import_parser("pymavlink.mavutil", path)
    found: _Messages = defaultdict(list)
    with parsing(path, "a MAVLink telemetry log"):
        log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
        try:
            while (m := log.recv_match(type=_TYPES)) is not None:
                if m.get_type() in _TYPES:
                    found[m.get_type()].append(
                        (float(m._timestamp), (m.get_srcSystem(), m.get_srcComponent()), m))
        finally:
            log.close()
    if not found:
        raise LogFormatError(f"{path}: no MAVLink messages with pose, rotor speeds or motor "
                             "outputs (is it a telemetry log?)")
    return found


def _from_autopilot(found: _Messages, mavlink: ModuleType) -> _Messages:
    """The messages sent by the autopilot (all of them if no autopilot HEARTBEAT).

    ``mavlink`` is pymavlink's dialect module, for the MAVLink enums: a ground station's
    HEARTBEAT says type GCS or autopilot INVALID.
    """
    beats = [src for _, src, m in found.get("HEARTBEAT", [])
             if m.autopilot != mavlink.MAV_AUTOPILOT_INVALID and m.type != mavlink.MAV_TYPE_GCS]
    if not beats:
        return found
    return {name: [row for row in rows if row[1] == beats[0]] for name, rows in found.items()}


#: Receipt-time span, s, over which the fastest message's lag stands for the clock offset:
#: long enough to hold a fast message, short enough to follow a clock that stops (a
#: lock-stepped simulator waiting for its peer) or drifts.
LAG_WINDOW = 2.0


def _receipt_clock(own: _Messages) -> Callable[[np.ndarray], np.ndarray] | None:
    """Receipt time → autopilot time, s (see the module docstring), or None."""
    pairs = [(receipt, receipt - m.time_boot_ms * 1e-3)
             for name in _CLOCKED for receipt, _, m in own.get(name, [])]
    # SERVO_OUTPUT_RAW's time_usec is the same clock (it wraps, but that only raises lags).
    pairs += [(receipt, receipt - m.time_usec * 1e-6)
              for receipt, _, m in own.get("SERVO_OUTPUT_RAW", [])]
    if not pairs:
        return None
    receipt, lag = np.array(sorted(pairs)).T
    window = np.floor((receipt - receipt[0]) / LAG_WINDOW)
    starts = np.flatnonzero(np.r_[True, np.diff(window) > 0])
    fastest = np.minimum.reduceat(lag, starts)
    edges = receipt[starts]

    def to_autopilot(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 1)
        return t - fastest[j]

    return to_autopilot


def _unwrap_us(ticks: np.ndarray) -> np.ndarray:
    """A uint32 microsecond counter (wraps every 71.6 min) made monotonic, in s."""
    steps = np.diff(ticks, prepend=ticks[:1])
    wraps = np.cumsum(steps < -(2.0**31))
    return (ticks + wraps * 2.0**32) * 1e-6


def _pose(found: _Messages, own: _Messages, clock: Callable[[np.ndarray], np.ndarray]
          ) -> _Pose:
    """Motion-capture pose, else local position and attitude (NED/FRD); the pose's origin."""
    mocap = found.get("ATT_POS_MOCAP", [])
    if mocap:
        t = clock(np.array([r for r, _, _ in mocap]))
        p = np.array([[m.x, m.y, m.z] for _, _, m in mocap], dtype=float)
        q = np.array([list(m.q) for _, _, m in mocap], dtype=float)
        return Series(t, np.column_stack([p, q]), "ATT_POS_MOCAP"), None, None, "motion_capture"
    local = own.get("LOCAL_POSITION_NED", [])
    if not local:
        return None, None, None, "autopilot"
    position = Series(np.array([m.time_boot_ms * 1e-3 for _, _, m in local]),
                      np.array([[m.x, m.y, m.z] for _, _, m in local], dtype=float),
                      "LOCAL_POSITION_NED")
    if own.get("ATTITUDE_QUATERNION"):
        rows = own["ATTITUDE_QUATERNION"]
        q = np.array([[m.q1, m.q2, m.q3, m.q4] for _, _, m in rows], dtype=float)
        label = "ATTITUDE_QUATERNION"
    elif own.get("ATTITUDE"):
        rows = own["ATTITUDE"]
        q = euler_ned_to_quaternion(*np.array([[m.roll, m.pitch, m.yaw] for _, _, m in rows],
                                              dtype=float).T)
        label = "ATTITUDE"
    else:
        return None, None, None, "autopilot"
    attitude = Series(np.array([m.time_boot_ms * 1e-3 for _, _, m in rows]), q, label)
    return None, position, attitude, "autopilot"


def _esc_rotors(path: Path, own: _Messages, clock: Callable[[np.ndarray], np.ndarray],
                k: int) -> tuple[Series, ...]:
    """Rotor speeds from ESC_TELEMETRY_*: as many rotors as ESCs that ever turned."""
    present = {name: own[name] for name in ESC_TELEMETRY if own.get(name)}
    turned = [base + j for name, base in ESC_TELEMETRY.items() if name in present
              for j in range(4) if any(m.rpm[j] for _, _, m in present[name])]
    # An ESC never turning is a rotor of this vehicle only if the config says so.
    count = max(turned) + 1 if turned else k
    series = []
    for name, base in ESC_TELEMETRY.items():
        if base >= count:
            break
        rows = present.get(name)
        if not rows:
            raise LogFormatError(f"{path}: ESC rpm for rotors {base + 1}..{base + 4} missing "
                                 f"(no {name}) while rotors up to {count} report theirs")
        width = min(4, count - base)
        t = clock(np.array([r for r, _, _ in rows]))
        rpm = np.array([list(m.rpm)[:width] for _, _, m in rows], dtype=float)
        series.append(Series(t, rpm * RPM_TO_RAD_S, f"{name} rpm"))
    return tuple(series)


def _servo_outputs(own: _Messages) -> MotorOutputs | None:
    """SERVO_OUTPUT_RAW port 0 channels 1..k that drive motors, PWM µs, as logged."""
    rows = [m for _, _, m in own.get("SERVO_OUTPUT_RAW", []) if m.port == 0]
    if not rows:
        return None
    pwm = np.array([[getattr(m, f"servo{i}_raw", 0) or 0 for i in range(1, 17)] for m in rows],
                   dtype=float)
    count = motor_output_count(pwm)
    if count == 0:
        return None
    t = _unwrap_us(np.array([m.time_usec for m in rows], dtype=float))
    return MotorOutputs(Series(t, pwm[:, :count], "SERVO_OUTPUT_RAW PWM"), "pwm")


# --- IMU ---------------------------------------------------------------------------------


def _battery(own: _Messages, clock: Callable[[np.ndarray], np.ndarray]) -> Series | None:
    """SYS_STATUS battery voltage, V, on the autopilot's clock; None without one."""
    rows = own.get("SYS_STATUS", [])
    if not rows:
        return None
    t = clock(np.array([receipt for receipt, _, _ in rows]))
    volts = np.array([m.voltage_battery for _, _, m in rows], float) / 1000.0
    return Series(t, volts[:, None], "SYS_STATUS voltage_battery")


def _parameters(own: _Messages) -> dict[str, float]:
    """The autopilot's PARAM_VALUEs in the log, by name (the last of each)."""
    return {str(m.param_id): float(m.param_value) for _, _, m in own.get("PARAM_VALUE", [])}


def _imu_times(rows: list[tuple[float, tuple[int, int], Any]],
               clock: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The rows' autopilot times, s: time_boot_ms, or time_usec since boot (a Unix
    time_usec: the receipt time mapped onto the autopilot clock)."""
    m = rows[0][2]
    if hasattr(m, "time_boot_ms"):
        return np.array([r[2].time_boot_ms * 1e-3 for r in rows])
    usec = np.array([r[2].time_usec for r in rows], dtype=float)
    receipt = clock(np.array([r[0] for r in rows]))
    return np.where(usec < _EPOCH_USEC, usec * 1e-6, receipt)


def _imu_rows(own: _Messages, name: str, autopilot: int | None, mavlink: ModuleType
              ) -> list[tuple[float, tuple[int, int], Any]]:
    """The rows of one IMU message that are the primary IMU's and in known units."""
    rows = own.get(name, [])
    if name in ("HIGHRES_IMU", "RAW_IMU"):
        # Their field ``id`` names the IMU (not the message id).
        rows = [r for r in rows if "id" not in r[2].get_fieldnames() or int(r[2].id or 0) == 0]
    if name == "RAW_IMU" and autopilot != mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return []
    return rows


def _highres(rows: list[tuple[float, tuple[int, int], Any]],
             clock: Callable[[np.ndarray], np.ndarray]
             ) -> tuple[Series | None, Series | None]:
    """HIGHRES_IMU gyro and accelerometer, each of the rows that flag it updated."""
    t = _imu_times(rows, clock)
    flags = np.array([int(m.fields_updated) for _, _, m in rows])
    values = np.array([[m.xgyro, m.ygyro, m.zgyro, m.xacc, m.yacc, m.zacc] for _, _, m in rows],
                      dtype=float)
    flagged = flags.any()  # a sender that sets no flag at all: every row counts
    out = []
    for bits, columns, what in ((_HIGHRES_GYRO, slice(0, 3), "gyro"),
                                (_HIGHRES_ACCEL, slice(3, 6), "acc")):
        keep = (flags & bits) != 0 if flagged else np.ones(t.size, dtype=bool)
        out.append(Series(t[keep], values[keep, columns], f"HIGHRES_IMU x{what}..z{what}")
                   if keep.any() else None)
    return out[0], out[1]


def _scaled(name: str, rows: list[tuple[float, tuple[int, int], Any]],
            clock: Callable[[np.ndarray], np.ndarray]
            ) -> tuple[Series, Series]:
    """SCALED_IMU* / RAW_IMU (ArduPilot) gyro (mrad/s) and accelerometer (mG), in SI."""
    t = _imu_times(rows, clock)
    values = np.array([[m.xgyro, m.ygyro, m.zgyro, m.xacc, m.yacc, m.zacc] for _, _, m in rows],
                      dtype=float) * 1e-3
    return (Series(t, values[:, :3], f"{name} xgyro..zgyro"),
            Series(t, values[:, 3:] * STANDARD_GRAVITY, f"{name} xacc..zacc"))


def _imu(own: _Messages, clock: Callable[[np.ndarray], np.ndarray], mavlink: ModuleType
         ) -> tuple[Series | None, Series | None, list[str]]:
    """The primary IMU's gyro and accelerometer (module docstring); notes."""
    beats = [m for _, _, m in own.get("HEARTBEAT", [])]
    autopilot = int(beats[0].autopilot) if beats else None
    gyro = accel = None
    notes = []
    for name in IMU_MESSAGES:
        rows = _imu_rows(own, name, autopilot, mavlink)
        if not rows:
            continue
        g, a = _highres(rows, clock) if name == "HIGHRES_IMU" else _scaled(name, rows, clock)
        if gyro is None and g is not None:
            gyro, notes = g, notes + ([f"the gyro is {name}'s, not the first IMU's"]
                                      if name.endswith(("2", "3")) else [])
        if accel is None and a is not None:
            accel = a
    if own.get("RAW_IMU") and not _imu_rows(own, "RAW_IMU", autopilot, mavlink) \
            and gyro is None:
        notes.append("RAW_IMU of an autopilot other than ArduPilot holds raw sensor counts; "
                     "not read")
    if gyro is None and own.get("ATTITUDE"):
        rows = own["ATTITUDE"]
        gyro = Series(np.array([m.time_boot_ms * 1e-3 for _, _, m in rows]),
                      np.array([[m.rollspeed, m.pitchspeed, m.yawspeed] for _, _, m in rows],
                               dtype=float), "ATTITUDE rollspeed..yawspeed (AHRS body rates)")
    return gyro, accel, notes


def _imu_settings(own: _Messages, gyro: Series | None, accel: Series | None
                  ) -> tuple[tuple[float, float, float] | None, ImuFilter | None]:
    """The IMU's position (m, body FRD) and filter, from the PARAM_VALUEs in the log."""
    parameters = _parameters(own)
    position = None
    for names in (("INS_POS1_X", "INS_POS1_Y", "INS_POS1_Z"),
                  ("EKF2_IMU_POS_X", "EKF2_IMU_POS_Y", "EKF2_IMU_POS_Z")):
        if all(name in parameters for name in names):
            x, y, z = (parameters[name] for name in names)
            position = (x, y, z)
            break
    # ArduPilot's IMU messages and ATTITUDE rates are its filtered samples.
    ardupilot = [s is not None and not s.label.startswith("HIGHRES") for s in (gyro, accel)]
    stated = [n for n in ("INS_GYRO_FILTER", "INS_ACCEL_FILTER") if n in parameters]
    if not stated or not any(ardupilot):
        return position, None
    return position, ImuFilter(parameters.get("INS_GYRO_FILTER") if ardupilot[0] else None,
                               parameters.get("INS_ACCEL_FILTER") if ardupilot[1] else None,
                               ", ".join(f"PARAM_VALUE {n}" for n in stated))


def _modes(own: _Messages, mavutil: ModuleType, clock: Callable[[np.ndarray], np.ndarray]
           ) -> ModeChanges | None:
    """The modes of the autopilot's HEARTBEATs, periodic reports; None without any."""
    beats = own.get("HEARTBEAT", [])
    if not beats:
        return None
    t = clock(np.array([r for r, _, _ in beats]))
    modes = tuple(mavutil.mode_string_v10(m) for _, _, m in beats)
    return ModeChanges(t=t, modes=modes, events=False, end=float(t[-1]))


def read_tlog(path: Path, vehicle: VehicleConfig) -> ParsedLog:
    """Read the pose, rotor speeds, motor outputs, IMU and modes of a telemetry log.

    Parameters
    ----------
    path : Path
        The ``.tlog`` file.
    vehicle : VehicleConfig
        The vehicle: its rotor count and motor curve (for SERVO_OUTPUT_RAW).

    Returns
    -------
    ParsedLog
        NED/FRD, rad/s, m/s², the autopilot's motor numbering, on the autopilot's clock
        (see the module docstring); with the modes of its HEARTBEATs.

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    found = _collect(path)
    mavutil = import_parser("pymavlink.mavutil", path)
    own = _from_autopilot(found, mavutil.mavlink)
    notes: list[str] = []
    clock = _receipt_clock(own)
    if clock is None:
        first = min(rows[0][0] for rows in found.values())
        clock = lambda t: np.asarray(t, dtype=float) - first  # noqa: E731
        notes.append(f"{path}: no autopilot time_boot_ms in the log; times are its receipt "
                     "times from the first message")
    rotor_notes = []
    with parsing(path, "a MAVLink telemetry log with the usual message fields"):
        pose, position, attitude, pose_source = _pose(found, own, clock)
        outputs = _servo_outputs(own)
        escs: tuple[Series, ...] = ()
        if any(own.get(name) for name in ESC_TELEMETRY):
            rotors = escs = _esc_rotors(path, own, clock, vehicle.rotor_count)
        elif outputs is not None:
            speeds, said = commanded_rotor_speeds(
                str(path), outputs.series, "SERVO_OUTPUT_RAW", _battery(own, clock),
                "SYS_STATUS", vehicle)
            rotors = (speeds,)
            rotor_notes += said
        else:
            raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no "
                                 "ESC_TELEMETRY_* rpm, no SERVO_OUTPUT_RAW)")
        modes = _modes(own, mavutil, clock)
        gyro, accel, imu_notes = _imu(own, clock, mavutil.mavlink)
        imu_position, imu_filter = _imu_settings(own, gyro, accel)
    notes += [f"{path}: {note}" for note in imu_notes]
    return ParsedLog(source=str(path), pose=pose, position=position, attitude=attitude,
                     pose_source=pose_source, pose_hint=_POSE_HINT, rotors=rotors,
                     notes=tuple(notes), rotor_notes=tuple(rotor_notes), modes=modes,
                     gyro=gyro, accel=accel, imu_position=imu_position, imu_filter=imu_filter,
                     motor_outputs=outputs, esc_speeds=escs)
