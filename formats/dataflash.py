"""ArduPilot DataFlash logs (``.bin``): the encoding, ArduPilot's messages, writer and reader.

Encoding: a stream of messages, each ``0xA3 0x95``, a one-byte type id and the packed
fields (little-endian, no padding). The log describes itself: an ``FMT`` message (type
128) gives each other type's id, length, name, format characters and column names, as
ArduPilot's ``AP_Logger`` writes them (``libraries/AP_Logger/LogStructure.h``). pymavlink's
`DFFormat` turns format characters into the struct layout, so `write_dataflash` packs
exactly what pymavlink's ``DFReader`` unpacks (pymavlink itself has no log writer), and
`read_dataflash` reads with ``DFReader``. Values are written as stored: the scaled format
characters (``c``/``C`` int16/uint16 × 100, ``e``/``E`` int32/uint32 × 100, ``L``
latitude/longitude × 1e7) take the scaled integer, and the text characters (``n``,
``N``, ``Z``: char[4], char[16], char[64]) take bytes; DFReader applies the scale when
reading, so centi-degree ``ATT`` (``"QccccCCCC"``) and float-degree ``ATT``
(``"QffffffB"``) both read in degrees.

ArduPilot's messages, every generation (``LogStructure.h`` and its per-library
successors; `ARDUPILOT_MESSAGES` holds those a simulated ArduCopter 4.5 flight is written
with). Time is ``TimeUS`` (µs since boot, ArduCopter 3.3 and later) or ``TimeMS`` (ms,
3.2 and earlier). Frames are NED/FRD.

Pose, in order of preference:

1. ``VISP`` (vision position: what a motion-capture or vision system sent the vehicle):
   ``TimeUS,RTimeUS,CTimeMS,PX,PY,PZ,Roll,Pitch,Yaw,…`` (m NED, deg Z-Y-X), at CTimeMS
   (the measurement's time on the autopilot clock, corrected for the link), else TimeUS.
   ``pose_source = "motion_capture"``.
2. EKF3 position ``XKF1`` PN, PE, PD with its quaternion ``XKQ`` Q1..Q4.
3. EKF2 position ``NKF1`` with ``NKQ``.
4. An EKF position (``XKF1``, ``NKF1``, or the 3.2-era EKF1 ``TimeMS,…,PN,PE,PD``) with
   ``ATT`` Roll, Pitch, Yaw.
5. ``POS`` Lat, Lng (deg), Alt (m), made local about the first sample, with ``ATT``.

2–5 are the autopilot's estimate (``pose_source = "autopilot"``). Copter writes ``XKF1``
and ``XKQ`` at 25 Hz from its 25 Hz logging loop with LOG_BITMASK's ATTITUDE_FAST
(``Copter::twentyfive_hz_logging``). EKF cores (multi-IMU): ArduPilot 4.x tags each row
with core index ``C`` (``XKF1`` ``"QBccCfffffffccce"``, ``XKQ``/``NKQ`` ``"QBffff"
TimeUS,C,Q1..Q4``); 3.5–3.6 logged core 0 as ``XKF1``/``XKQ1`` and core 1 as
``XKF6``/``XKQ2`` (``NKF1``/``NKQ1``, ``NKF6``/``NKQ2`` for EKF2). The primary core is the
most frequent ``PI`` (primary index) of ``XKF4``/``NKF4`` when logged and present, else
the lowest core: one core throughout keeps the pose continuous across lane switches.

Rotor speeds: ESC rpm, else motor outputs. ESC instance i and output channel i + 1 are
the autopilot's motor i + 1.

- ``ESC`` ``TimeUS,Instance,RPM,…`` (ArduPilot 4.x, one message per ESC and update;
  ``RPM`` a float in rpm, or ``e`` = int32 × 100 rpm in some 4.x versions). Bidirectional
  DShot and ESC telemetry both log here.
- ``ESC1``…``ESC8`` (ArduCopter 3.3–3.6): ``"Qcccc" TimeUS,RPM,Volt,Curr,Temp`` (earlier
  ``"Icccc" TimeMS,…``), written as ``rpm: (int16_t)(esc_rpm/10)``: with the ``c`` scale
  the field reads rpm / 1000. Later ``"QeCCcH" TimeUS,RPM,Volt,Curr,Temp,CTot`` (``e``,
  unit rpm, multiplier 1e-2): the field reads rpm.
- ``RCOU`` PWM, µs: ``"Ihhhhhhhh" TimeMS,Chan1..Chan8`` (ArduCopter 3.1/3.2),
  ``"Ihhhhhhhhhhhh" TimeMS,Ch1..Ch12``, ``"Q{h,H}×14" TimeUS,C1..C14`` (3.3 on), at 10 Hz
  (``Copter::ten_hz_logging_loop``), through the vehicle's `[motor]` curve. ``RCO2``
  (C15..C18) and ``RCO3`` (C19..C32) are not read: the motors are taken as the leading
  output channels.

Modes: ``MODE`` at each change (``Mode``, ``ModeNum``, ``Rsn`` the reason).

IMU, of instance 0 (the first IMU), body FRD, gyro in rad/s, accelerometer the specific
force in m/s² (AccZ ≈ −9.81 level at rest), the first present of:

1. ``GYR`` / ``ACC`` ``"QBQfff" TimeUS,I,SampleUS,GyrX..`` (raw IMU logging, LOG_BITMASK
   IMU_RAW, at the sensor rate; older logs: ``GYR1``/``ACC1``, one name per instance), at
   ``SampleUS``, the sensor's own time. INS_RAW_LOG_OPT bit 2 alone logs them after the
   low-pass filter; otherwise they are taken before it (with bit 3 the filtered copies are
   instances ``I + count``, never read).
2. ``IMU`` ``"QBffffffIIfBBHH" TimeUS,I,GyrX,..,AccZ,EG,EA,T,GH,AH,GHz,AHz`` (3.x: no ``I``;
   ``IMU2``, ``IMU3`` the other instances), the low-passed samples the attitude controller
   uses, at 25 Hz (LOG_BITMASK IMU, Copter's 25 Hz loop) or the loop rate (IMU_FAST,
   ``Copter::loop_rate_logging``).
3. The batch sampler (INS_LOG_BAT_MASK): ``ISBH`` ``"QHBBHHQf"
   TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate`` heads batch ``N`` of
   ``smp_cnt`` samples of one sensor (``type`` `ISB_ACCEL` or `ISB_GYRO`) sampled at
   ``smp_rate`` Hz from ``SampleUS``; its ``ISBD`` ``"QHHaaa" TimeUS,N,seqno,x,y,z``
   messages each carry 32 int16 samples per axis, sample j of ``seqno`` being sample
   32 seqno + j, in m/s² or rad/s × ``mul`` (``AP_InertialSensor::BatchSampler``). The
   batches of one sensor come in bursts, with gaps while the others are sampled. Raw
   samples unless INS_LOG_BAT_OPT bit 1 (post-filter).
4. Gyro only: ``RATE`` ``R, P, Y`` (deg/s), the AHRS body rates (filtered gyro less the
   EKF's bias estimate).

Its position is ``PARM`` INS_POS1_X/Y/Z (m, body FRD, from the centre of gravity), its
filter INS_GYRO_FILTER / INS_ACCEL_FILTER (Hz; `mavsysid.formats.parsed_log.ImuFilter`,
0 for raw samples).
"""

from __future__ import annotations

import math
import re
import struct
from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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

from mavsysid.errors import LogFormatError

__all__ = ["ARDUPILOT_MESSAGES", "FMT_TYPE", "HEADER", "ISB_ACCEL", "ISB_GYRO", "MODE_REASONS",
           "RCOU_OUTPUTS", "DataFlashFormat", "read_dataflash", "read_dataflash_modes",
           "write_dataflash"]

#: The two bytes that start every message.
HEADER = bytes([0xA3, 0x95])
#: Type id of the FMT message, fixed by the format.
FMT_TYPE = 0x80
_FMT_FORMAT = "BBnNZ"
_FMT_COLUMNS = "Type,Length,Name,Format,Columns"
_TEXT = frozenset("nNZ")  # format characters of text columns

#: One message type: (type id, format characters, comma-separated column names).
DataFlashFormat = tuple[int, str, str]

#: The messages of a simulated ArduCopter 4.5 flight, as (type id, format, columns); ids
#: are the log's own choice.
ARDUPILOT_MESSAGES: dict[str, DataFlashFormat] = {
    "PARM": (64, "QNff", "TimeUS,Name,Value,Default"),
    "MSG": (91, "QZ", "TimeUS,Message"),
    "MODE": (11, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "XKF1": (181, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,"
                                      "GX,GY,GZ,OH"),
    "XKQ": (188, "QBffff", "TimeUS,C,Q1,Q2,Q3,Q4"),
    "ESC": (153, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
    "RCOU": (34, "QHHHHHHHHHHHHHH", "TimeUS," + ",".join(f"C{i}" for i in range(1, 15))),
    "IMU": (57, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,"
                                   "AHz"),
}
#: MODE.Rsn (ModeReason) of a mode set by the pilot's radio or by a ground station.
MODE_REASONS: dict[str, int] = {"RC_COMMAND": 1, "GCS_COMMAND": 2}
#: Output channels RCOU logs (C1..C14).
RCOU_OUTPUTS = 14

#: ISBH ``type`` of an accelerometer and of a gyro batch (AP_InertialSensor's
#: IMU_SENSOR_TYPE).
ISB_ACCEL, ISB_GYRO = 0, 1
#: Samples per axis in one ISBD message (int16[32] x, y, z).
_ISB_SAMPLES = 32
_GYRO_FIELDS = ["GyrX", "GyrY", "GyrZ"]
_ACCEL_FIELDS = ["AccX", "AccY", "AccZ"]

#: Per-ESC messages of ArduCopter 3.3–3.6, ESCn = ESC instance n − 1.
_ESC_TYPES = tuple(f"ESC{i}" for i in range(1, 9))
_MOTOR_TYPES = ("ESC", *_ESC_TYPES, "RCOU")
# RCOU output channel fields across generations: Chan1.., Ch1.., C1...
_CHANNEL = re.compile(r"^(?:Chan|Ch|C)(\d+)$")
# ESCn RPM logged as int16 rpm/10 under the "c" (× 0.01) format: it reads rpm / 1000.
_CENTI_DECA_RPM = 1000.0
_EARTH_RADIUS = 6378137.0  # m, WGS-84 equatorial: a local flat-earth map is enough here

#: Parsed DataFlash messages by type name, in log order.
_Messages = dict[str, list[Any]]


# --- writing -----------------------------------------------------------------------------


def write_dataflash(path: Path, formats: Mapping[str, DataFlashFormat],
                    rows: Iterable[tuple[str, tuple[Any, ...] | Mapping[str, Any]]]) -> None:
    """Write a DataFlash log: an FMT message for each type, then the data messages.

    Parameters
    ----------
    path : Path
        The ``.bin`` file to write (replaced if present).
    formats : mapping of str to (int, str, str)
        Message name (at most 4 characters) → (type id, not 128; format characters, e.g.
        ``"QBffff"``; column names, e.g. ``"TimeUS,C,Q1,Q2,Q3,Q4"``).
    rows : iterable of (str, tuple or mapping)
        Data messages in file order: (message name, its values as stored), the values
        one per column or by column name (a column not named is 0, or empty text).

    Raises
    ------
    ValueError
        A type id used twice or reserved for FMT, a name longer than 4 characters, or a
        column count that does not match the format.
    KeyError
        A row of a message name not in ``formats``, or naming a column its message lacks.
    struct.error
        A value that does not fit its format character.
    """
    from pymavlink.DFReader import DFFormat

    ids = [tid for tid, _, _ in formats.values()]
    if len(set(ids)) != len(ids) or FMT_TYPE in ids:
        raise ValueError(f"DataFlash type ids must be distinct and not {FMT_TYPE}: {ids}")
    fmt_fmt = DFFormat(FMT_TYPE, "FMT", 89, _FMT_FORMAT, _FMT_COLUMNS)
    parsed: dict[str, Any] = {}
    for name, (tid, fmt, columns) in formats.items():
        if len(name) > 4 or len(fmt) != len(columns.split(",")):
            raise ValueError(f"DataFlash message {name!r}: a name of at most 4 characters "
                             f"and one column per format character, got {fmt!r}, {columns!r}")
        parsed[name] = DFFormat(tid, name, 0, fmt, columns)

    def message(f: Any, values: Iterable[Any]) -> bytes:
        return HEADER + bytes([f.type]) + struct.pack(f.msg_struct, *values)

    def by_column(f: Any, values: Mapping[str, Any]) -> tuple[Any, ...]:
        unknown = set(values) - set(f.columns)
        if unknown:
            raise KeyError(f"DataFlash message {f.name}: no column {sorted(unknown)}")
        return tuple(values.get(c, b"" if kind in _TEXT else 0)
                     for c, kind in zip(f.columns, f.format, strict=True))

    out = bytearray(message(fmt_fmt, (FMT_TYPE, 89, b"FMT", _FMT_FORMAT.encode(),
                                      _FMT_COLUMNS.encode())))
    for name, f in parsed.items():
        length = len(HEADER) + 1 + struct.calcsize(f.msg_struct)
        out += message(fmt_fmt, (f.type, length, name.encode(), f.format.encode(),
                                 ",".join(f.columns).encode()))
    for name, values in rows:
        f = parsed[name]
        out += message(f, by_column(f, values) if isinstance(values, Mapping) else values)
    Path(path).write_bytes(bytes(out))


# --- fields ------------------------------------------------------------------------------


def _has_fields(rows: list[Any], names: list[str]) -> bool:
    """Whether the messages (all of one type) have every named field."""
    return bool(rows) and all(n in rows[0].get_fieldnames() for n in names)


def _field_array(rows: list[Any], names: list[str]) -> np.ndarray:
    """The named fields of the messages as floats, shape (len(rows), len(names))."""
    return np.array([[getattr(m, n) for n in names] for m in rows], dtype=float).reshape(
        len(rows), len(names))


def _field_format(rows: list[Any], name: str) -> str:
    """The DataFlash format character of a field (``"f"``, ``"c"``, ``"e"``…)."""
    fmt = rows[0].fmt
    return fmt.format[fmt.colhash[name]]


#: Frequent messages whose time stamps place an untimed MODE (ArduCopter before 3.3).
_CLOCK_TYPES = ("ATT", "IMU", "RCOU", "CTUN")


def _row_time(m: Any) -> float | None:
    """One message's ``TimeUS`` or ``TimeMS``, s since boot; None if it has neither."""
    fields = m.get_fieldnames()
    if "TimeUS" in fields:
        return float(m.TimeUS) * 1e-6
    if "TimeMS" in fields:
        return float(m.TimeMS) * 1e-3
    return None


def _message_times(rows: list[Any]) -> np.ndarray:
    """Message times, s since boot, from ``TimeUS`` or (older logs) ``TimeMS``.

    Raises
    ------
    KeyError
        Neither field (the caller's parsing guard turns it into a one-line error).
    """
    if _has_fields(rows, ["TimeUS"]):
        return _field_array(rows, ["TimeUS"])[:, 0] * 1e-6
    if _has_fields(rows, ["TimeMS"]):
        return _field_array(rows, ["TimeMS"])[:, 0] * 1e-3
    raise KeyError(f"no TimeUS or TimeMS field in {rows[0].get_type()}")


# --- pose --------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Ekf:
    """Where one EKF generation logs its position, quaternion and primary core."""

    position: str  # tagged with C in 4.x, else core 0
    position_cores: dict[str, int]  # 3.5–3.6 per-core names
    attitude: str
    attitude_cores: dict[str, int]
    status: tuple[str, ...]  # messages with the PI (primary index) field


_EKF3 = _Ekf("XKF1", {"XKF1": 0, "XKF6": 1}, "XKQ", {"XKQ1": 0, "XKQ2": 1}, ("XKF4", "XKF9"))
_EKF2 = _Ekf("NKF1", {"NKF1": 0, "NKF6": 1}, "NKQ", {"NKQ1": 0, "NKQ2": 1}, ("NKF4", "NKF9"))
_EKF1 = _Ekf("EKF1", {"EKF1": 0}, "", {}, ())

_POSE_TYPES = ("VISP", "POS", "ATT", *(name for ekf in (_EKF3, _EKF2, _EKF1) for name in (
    ekf.position, *ekf.position_cores, ekf.attitude, *ekf.attitude_cores, *ekf.status) if name))
_POSE_HINT = ("no VISP, nor XKF1 with XKQ, NKF1 with NKQ, XKF1, NKF1 or EKF1 with ATT, or POS "
              "with ATT")
_IMU_TYPES = ("IMU", "GYR", "ACC", "GYR1", "ACC1", "ISBH", "ISBD", "RATE", "PARM")
_TYPES = [*_POSE_TYPES, *_MOTOR_TYPES, *_IMU_TYPES, "BAT"]

# pose (m = 7) or position and attitude, and where the pose comes from.
_Pose = tuple[Series | None, Series | None, Series | None, PoseSource]


def _by_core(found: _Messages, tagged: str, split: dict[str, int]) -> dict[int, list[Any]]:
    """Rows by EKF core: from the C field of `tagged`, else from per-core names."""
    cores: dict[int, list[Any]] = defaultdict(list)
    rows = found.get(tagged, [])
    if _has_fields(rows, ["C"]):
        for m in rows:
            cores[int(m.C)].append(m)
        return dict(cores)
    for name, core in split.items():
        if found.get(name):
            cores[core] = found[name]
    return dict(cores)


def _primary(found: _Messages, ekf: _Ekf, usable: set[int]) -> int:
    """The core flagged primary most often (XKF4/NKF4 PI) if usable, else the lowest."""
    flagged = Counter(int(m.PI) for name in ekf.status for m in found.get(name, [])
                      if "PI" in m.get_fieldnames())
    for core, _ in flagged.most_common():
        if core in usable:
            return core
    return min(usable)


def _degrees_to_quaternion(rows: list[Any]) -> np.ndarray:
    return euler_ned_to_quaternion(*np.radians(_field_array(rows, ["Roll", "Pitch", "Yaw"])).T)


def _local_from_global(rows: list[Any]) -> np.ndarray:
    """POS latitude, longitude (deg) and altitude (m) → NED, m, about the first sample."""
    lat, lng, alt = _field_array(rows, ["Lat", "Lng", "Alt"]).T
    north = np.radians(lat - lat[0]) * _EARTH_RADIUS
    east = np.radians(lng - lng[0]) * _EARTH_RADIUS * np.cos(np.radians(lat[0]))
    return np.column_stack([north, east, -(alt - alt[0])])


def _vision(found: _Messages) -> Series:
    rows = found["VISP"]
    corrected = _field_array(rows, ["CTimeMS"])[:, 0] * 1e-3
    t = np.where(corrected > 0.0, corrected, _message_times(rows))
    p = _field_array(rows, ["PX", "PY", "PZ"])
    q = _degrees_to_quaternion(rows)
    return Series(t, np.column_stack([p, q]), "VISP")


def _ekf_position(found: _Messages, ekf: _Ekf, need_attitude: bool
                  ) -> tuple[Series, Series | None] | None:
    """The primary core's EKF position and (if logged) quaternion, or None."""
    positions = _by_core(found, ekf.position, ekf.position_cores)
    attitudes = _by_core(found, ekf.attitude, ekf.attitude_cores) if ekf.attitude else {}
    usable = set(positions) & set(attitudes) if need_attitude else set(positions)
    if not usable:
        return None
    core = _primary(found, ekf, usable)
    rows = positions[core]
    label = f"{rows[0].get_type()} core {core}"
    position = Series(_message_times(rows), _field_array(rows, ["PN", "PE", "PD"]), label)
    if core not in attitudes:
        return position, None
    rows = attitudes[core]
    label = f"{rows[0].get_type()} core {core}"
    return position, Series(_message_times(rows), _field_array(rows, ["Q1", "Q2", "Q3", "Q4"]),
                            label)


def _att(found: _Messages) -> Series:
    rows = found["ATT"]
    return Series(_message_times(rows), _degrees_to_quaternion(rows), "ATT")


def _pose(found: _Messages) -> _Pose:
    """The best pose of a DataFlash log (module docstring), NED/FRD; its origin."""
    if found.get("VISP"):
        return _vision(found), None, None, "motion_capture"
    for ekf in (_EKF3, _EKF2):
        pair = _ekf_position(found, ekf, need_attitude=True)
        if pair is not None and pair[1] is not None:
            return None, pair[0], pair[1], "autopilot"
    if found.get("ATT"):
        for ekf in (_EKF3, _EKF2, _EKF1):
            pair = _ekf_position(found, ekf, need_attitude=False)
            if pair is not None:
                return None, pair[0], _att(found), "autopilot"
        if found.get("POS"):
            rows = found["POS"]
            position = Series(_message_times(rows), _local_from_global(rows), "POS")
            return None, position, _att(found), "autopilot"
    return None, None, None, "autopilot"


# --- rotors ------------------------------------------------------------------------------


def _rpm(rows: list[Any]) -> np.ndarray:
    """The RPM field in rpm, shape (N, 1), undoing the old ESCn int16 rpm/10 encoding."""
    rpm = _field_array(rows, ["RPM"])
    if rows[0].get_type() in _ESC_TYPES and _field_format(rows, "RPM") == "c":
        rpm = rpm * _CENTI_DECA_RPM
    return rpm


def _esc_rotors(path: Path, found: _Messages) -> tuple[Series, ...] | None:
    """One rotor-speed series per ESC instance 0..m−1, rad/s; None without ESC messages.

    Raises
    ------
    LogFormatError
        A gap in the instance numbers (rotor i missing while higher rotors report).
    """
    by_instance: dict[int, list[Any]] = defaultdict(list)
    for m in found.get("ESC", []):
        by_instance[int(m.Instance)].append(m)
    if not by_instance:
        for i, name in enumerate(_ESC_TYPES):
            if found.get(name):
                by_instance[i] = found[name]
    if not by_instance:
        return None
    count = max(by_instance) + 1
    missing = [i + 1 for i in range(count) if i not in by_instance]
    if missing:
        raise LogFormatError(f"{path}: ESC rpm of rotor(s) {', '.join(map(str, missing))} "
                             f"missing while rotors up to {count} report theirs")
    return tuple(Series(_message_times(by_instance[i]), _rpm(by_instance[i]) * RPM_TO_RAD_S,
                        f"ESC {i} rpm") for i in range(count))


def _rcou_channels(rows: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    """RCOU times (s) and PWM (µs), channels in output order, whatever their field names.

    Returns
    -------
    t : ndarray, shape (N,)
    pwm : ndarray, shape (N, k)
        Output channels 1..k (``Chan1``, ``Ch1`` or ``C1`` onwards).
    """
    numbered = sorted((int(match.group(1)), name) for name in rows[0].get_fieldnames()
                      if (match := _CHANNEL.match(name)))
    names = [name for _, name in numbered]
    return _message_times(rows), _field_array(rows, names)


# --- IMU ---------------------------------------------------------------------------------


def _parameters(found: _Messages) -> dict[str, float]:
    """The log's ``PARM`` values by name (the last one logged of each)."""
    return {str(m.Name): float(m.Value) for m in found.get("PARM", [])}


def _primary_rows(found: _Messages, name: str, old: str) -> list[Any]:
    """Rows of instance 0: ``I == 0`` of ``name`` (4.x), else all of ``name`` or ``old``
    (per-instance message names of older logs, whose first instance has no suffix or 1)."""
    rows = found.get(name, [])
    if _has_fields(rows, ["I"]):
        return [m for m in rows if int(m.I) == 0]
    return rows or found.get(old, [])


def _sample_times(rows: list[Any]) -> np.ndarray:
    """GYR/ACC sample times, s: ``SampleUS`` (when the sensor sampled) where set."""
    if _has_fields(rows, ["SampleUS"]):
        sample = _field_array(rows, ["SampleUS"])[:, 0]
        return np.where(sample > 0.0, sample, _field_array(rows, ["TimeUS"])[:, 0]) * 1e-6
    return _message_times(rows)


def _raw_option(parameters: Mapping[str, float], name: str, bit: int) -> bool:
    """Whether option ``bit`` of bitmask parameter ``name`` is set (absent: not set)."""
    value = parameters.get(name)
    return value is not None and math.isfinite(value) and (int(value) >> bit) & 1 == 1


def _fast_imu(found: _Messages, parameters: Mapping[str, float]
              ) -> tuple[Series | None, Series | None, bool]:
    """GYR and ACC instance 0 (raw IMU logging), and whether they are post-filter."""
    # INS_RAW_LOG_OPT bit 2: post-filter only; bit 3: pre- and post-filter, the post-filter
    # samples as instance + sensor count, so instance 0 stays the raw one.
    post = (_raw_option(parameters, "INS_RAW_LOG_OPT", 2)
            and not _raw_option(parameters, "INS_RAW_LOG_OPT", 3))
    out = []
    for name, old, fields in (("GYR", "GYR1", _GYRO_FIELDS), ("ACC", "ACC1", _ACCEL_FIELDS)):
        rows = _primary_rows(found, name, old)
        out.append(Series(_sample_times(rows), _field_array(rows, fields),
                          f"{rows[0].get_type()} {fields[0]}..Z (instance 0)")
                   if _has_fields(rows, fields) else None)
    return out[0], out[1], post


def _imu_message(found: _Messages) -> tuple[Series | None, Series | None]:
    """IMU instance 0 (``I == 0``; older logs: ``IMU``, the others ``IMU2``, ``IMU3``)."""
    rows = _primary_rows(found, "IMU", "IMU")
    if not _has_fields(rows, [*_GYRO_FIELDS, *_ACCEL_FIELDS]):
        return None, None
    t = _message_times(rows)
    return (Series(t, _field_array(rows, _GYRO_FIELDS), "IMU GyrX..Z (instance 0)"),
            Series(t, _field_array(rows, _ACCEL_FIELDS), "IMU AccX..Z (instance 0)"))


def _batches(found: _Messages) -> dict[int, Series]:
    """The batch sampler's samples of instance 0 by sensor type (`ISB_ACCEL`, `ISB_GYRO`).

    Each ``ISBH`` header starts a batch of ``smp_cnt`` samples of one sensor taken at
    ``smp_rate`` from ``SampleUS``; its ``ISBD`` messages (same ``N``) carry 32 samples
    each per axis as int16, sample j of message ``seqno`` being sample 32 seqno + j, in
    the sensor's unit × ``mul`` (m/s² or rad/s, body FRD). Batches of one sensor follow
    each other with gaps while the sampler logs the others.
    """
    headers = {int(m.N): m for m in found.get("ISBH", [])
               if int(m.instance) == 0 and float(m.smp_rate) > 0.0 and int(m.mul) > 0}
    data: dict[int, list[Any]] = defaultdict(list)
    for m in found.get("ISBD", []):
        if int(m.N) in headers:
            data[int(m.N)].append(m)
    times: dict[int, list[np.ndarray]] = defaultdict(list)
    values: dict[int, list[np.ndarray]] = defaultdict(list)
    for number, rows in sorted(data.items()):
        head = headers[number]
        for m in rows:
            block = np.column_stack([np.asarray(m.x, dtype=float), np.asarray(m.y, dtype=float),
                                     np.asarray(m.z, dtype=float)]) / float(head.mul)
            index = _ISB_SAMPLES * int(m.seqno) + np.arange(block.shape[0])
            keep = index < int(head.smp_cnt)
            times[int(head.type)].append(float(head.SampleUS) * 1e-6
                                         + index[keep] / float(head.smp_rate))
            values[int(head.type)].append(block[keep])
    return {kind: Series(np.concatenate(times[kind]), np.concatenate(values[kind]),
                         f"ISBD batch samples ({'gyro' if kind == ISB_GYRO else 'accel'}, "
                         "instance 0)") for kind in times}


def _rate_message(found: _Messages) -> Series | None:
    """RATE R, P, Y: the AHRS body rates (bias-corrected filtered gyro), deg/s → rad/s."""
    rows = found.get("RATE", [])
    if not _has_fields(rows, ["R", "P", "Y"]):
        return None
    return Series(_message_times(rows), np.radians(_field_array(rows, ["R", "P", "Y"])),
                  "RATE R, P, Y (AHRS body rates)")


def _imu_filter(parameters: Mapping[str, float], gyro_raw: bool, accel_raw: bool
                ) -> ImuFilter | None:
    """INS_GYRO_FILTER / INS_ACCEL_FILTER as they apply to the chosen samples."""
    stated = [name for name in ("INS_GYRO_FILTER", "INS_ACCEL_FILTER") if name in parameters]
    if not stated and not (gyro_raw or accel_raw):
        return None
    gyro = 0.0 if gyro_raw else parameters.get("INS_GYRO_FILTER")
    accel = 0.0 if accel_raw else parameters.get("INS_ACCEL_FILTER")
    source = ", ".join(f"PARM {name}" for name in stated) or "raw samples"
    return ImuFilter(gyro, accel, source)


def _imu_position(parameters: Mapping[str, float]) -> tuple[float, float, float] | None:
    """INS_POS1_X/Y/Z (m, body FRD), when all three are logged."""
    names = ("INS_POS1_X", "INS_POS1_Y", "INS_POS1_Z")
    if not all(name in parameters for name in names):
        return None
    x, y, z = (parameters[name] for name in names)
    return (x, y, z)


def _imu(found: _Messages) -> tuple[Series | None, Series | None, ImuFilter | None,
                                    tuple[float, float, float] | None]:
    """Gyro and accelerometer of the primary IMU, their filter and the IMU's position.

    Of each sensor the first present of: GYR/ACC (raw logging at the sensor rate), IMU
    (the filtered samples the attitude controller uses, at 25 Hz or the loop rate), the
    batch sampler (bursts at the sensor rate, with gaps), RATE (gyro only: the AHRS body
    rates).
    """
    parameters = _parameters(found)
    fast_gyro, fast_accel, post = _fast_imu(found, parameters)
    imu_gyro, imu_accel = _imu_message(found)
    batches = _batches(found)
    batch_raw = not _raw_option(parameters, "INS_LOG_BAT_OPT", 1)  # bit 1: post-filter
    kinds = []
    for fast, imu, batch in ((fast_gyro, imu_gyro, batches.get(ISB_GYRO)),
                             (fast_accel, imu_accel, batches.get(ISB_ACCEL))):
        if fast is not None:
            kinds.append((fast, not post))
        elif imu is not None:
            kinds.append((imu, False))
        elif batch is not None:
            kinds.append((batch, batch_raw))
        else:
            kinds.append((None, False))
    (gyro, gyro_raw), (accel, accel_raw) = kinds
    if gyro is None:
        gyro = _rate_message(found)
    if gyro is None and accel is None:
        return None, None, None, _imu_position(parameters)
    return gyro, accel, _imu_filter(parameters, gyro_raw, accel_raw), _imu_position(parameters)


# --- reading -----------------------------------------------------------------------------


def _collect(path: Path) -> _Messages:
    """The messages of the types used here, by type."""
    DFReader = import_parser("pymavlink.DFReader", path)
    found: _Messages = defaultdict(list)
    with parsing(path, "an ArduPilot DataFlash log"):
        log = DFReader.DFReader_binary(str(path))
        try:
            while (m := log.recv_match(type=_TYPES)) is not None:
                found[m.get_type()].append(m)
        finally:
            log.close()
    return found


def _battery(rows: list[Any]) -> Series | None:
    """The first battery's BAT.Volt, V, s since boot; None without one."""
    rows = [m for m in rows if getattr(m, "Inst", 0) == 0]
    if not rows:
        return None
    t = np.array([m.TimeUS for m in rows], float) * 1e-6
    return Series(t, np.array([[m.Volt] for m in rows], float), "BAT Volt")


def _rcou_outputs(rows: list[Any]) -> MotorOutputs | None:
    """RCOU PWM (µs) of the channels 1..k that drive motors; None if none ever outputs."""
    t, pwm = _rcou_channels(rows)
    count = motor_output_count(pwm)
    if count == 0:
        return None
    return MotorOutputs(Series(t, pwm[:, :count], "RCOU PWM"), "pwm")


def read_dataflash(path: Path, vehicle: VehicleConfig) -> ParsedLog:
    """Read the pose, rotor speeds, motor outputs and IMU of an ArduPilot DataFlash log.

    Parameters
    ----------
    path : Path
        The ``.bin`` file.
    vehicle : VehicleConfig
        The vehicle: its motor curve (for RCOU outputs).

    Returns
    -------
    ParsedLog
        NED/FRD, rad/s, m/s², ArduPilot's motor numbering, on the autopilot's clock (s
        since boot).

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    found = _collect(path)
    with parsing(path, "an ArduPilot DataFlash log with the usual message fields"):
        pose, position, attitude, pose_source = _pose(found)
        outputs = _rcou_outputs(found["RCOU"]) if found.get("RCOU") else None
        escs = _esc_rotors(path, found)
        gyro, accel, imu_filter, imu_position = _imu(found)
        notes = []
        if escs is not None:
            rotors = escs
        elif outputs is not None:
            speeds, said = commanded_rotor_speeds(str(path), outputs.series, "RCOU",
                                                  _battery(found["BAT"]), "BAT", vehicle)
            rotors = (speeds,)
            notes += said
        else:
            raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no ESC "
                                 "RPM, no RCOU)")
    return ParsedLog(source=str(path), pose=pose, position=position, attitude=attitude,
                     pose_source=pose_source, pose_hint=_POSE_HINT, rotors=rotors,
                     rotor_notes=tuple(notes), gyro=gyro, accel=accel,
                     imu_position=imu_position, imu_filter=imu_filter, motor_outputs=outputs,
                     esc_speeds=escs or ())


def read_dataflash_modes(path: Path) -> ModeChanges | None:
    """ArduPilot's flight modes over a DataFlash log (``MODE`` messages); None without.

    Parameters
    ----------
    path : Path
        The ``.bin`` file.

    Returns
    -------
    ModeChanges or None
        Mode changes at ``MODE`` times, s since boot, upper-case mode names (``Mode``
        where the log names it, else pymavlink's name of ``ModeNum``); the last mode
        holds to the log's end (``end`` inf). ArduCopter before 3.3 logged ``MODE`` with
        no time field (``"Mh" Mode,ThrCrs``, the mode a number): such a change is placed
        at the time of the last timed message before it in the file (`_CLOCK_TYPES`),
        where the autopilot wrote it; 0 before any.
    """
    reader = import_parser("pymavlink.DFReader", path)
    names = import_parser("pymavlink.mavutil", path).mode_mapping_acm
    times, modes = [], []
    last = 0.0
    with parsing(path, "an ArduPilot DataFlash log"):
        log = reader.DFReader_binary(str(path))
        try:
            while (m := log.recv_match(type=["MODE", *_CLOCK_TYPES])) is not None:
                t = _row_time(m)
                if m.get_type() != "MODE":
                    last = last if t is None else t
                    continue
                mode = getattr(m, "Mode", None)
                if not isinstance(mode, str):
                    mode = names.get(int(getattr(m, "ModeNum", mode)), "")
                times.append(last if t is None else t)
                modes.append(mode.upper())
        finally:
            log.close()
    if not times:
        return None
    return ModeChanges(t=np.array(times), modes=tuple(modes), events=True, end=math.inf)
