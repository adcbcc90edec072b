"""PX4 ULog files (``.ulg``): the encoding, PX4's topics and fields, writer and reader.

Encoding (PX4 user guide, "ULog File Format"): a 16-byte file header (magic ``ULog``,
version 1, start timestamp in µs), the flag-bits message, then the definitions section
(``I`` information, ``F`` formats), then the data section (``A`` add-logged subscriptions
and ``D`` data). `write_ulog` writes it (pyulog's own ``write_ulog`` only re-writes a file
it has parsed); `read_ulog` reads it with pyulog. Formats are given as PX4 writes them:
``"uint64_t timestamp;float[4] q;"``, nested types by name (``"esc_report[8] esc;"``).
Data rows are flattened field values keyed the way pyulog names them (``"q[0]"``,
``"esc[2].esc_rpm"``); a missing field is written as 0.

PX4's topics (``msg/`` of PX4 1.14/1.15; `PX4_TOPICS` holds the fields a simulated flight
is written with). Timestamps are µs since boot: ``timestamp_sample`` (the measurement
time) where the topic has it, else ``timestamp``. Frames are NED/FRD.

- Pose: ``vehicle_mocap_odometry``, else ``vehicle_visual_odometry`` (motion capture or
  vision forwarded to PX4: ``position[3]`` or, before PX4 1.14, ``x, y, z``, and ``q``
  [w, x, y, z]), else ``vehicle_local_position`` (x, y, z; also vx, vy, vz) with
  ``vehicle_attitude`` (q), the autopilot's estimate. An odometry ``pose_frame`` of FRD (a
  z-down world frame with arbitrary heading) is taken as NED, which only turns the world
  frame about the vertical, which the model does not see.
- Rotor speeds: ``esc_status`` ``esc[i].esc_rpm`` (up to `ESC_SLOTS`), measured, a
  magnitude. The ESCs are those whose ``actuator_function`` is a motor (101 = Motor1 …
  112), in motor order, where the log has that field; else ESCs 0..``esc_count`` − 1 (ESC
  i is motor i + 1).
- Motor commands: ``actuator_motors`` ``control[i]`` (`MOTOR_SLOTS`) is relative *thrust*
  (PX4 applies THR_MDL_FAC after it, in the output driver), so n = rotor_speed_max ·
  sqrt(control) — the motor curve with thrust_expo 0; NaN there means a stopped motor
  (n = 0), and a column that is NaN throughout an unused one. Else ``actuator_outputs``
  ``output[i]`` (taken as PWM in µs) through the vehicle's `[motor]` curve. Either is
  scaled by ``battery_status`` ``voltage_v`` (``voltage_filtered_v`` before PX4 1.14)
  over the curve's ``[motor] voltage`` where the vehicle file states it
  (`mavsysid.formats.motor_curve.on_battery`).
- Modes: ``vehicle_status`` ``nav_state`` (`NAVIGATION_STATES`), ``arming_state``.
- IMU (body FRD): ``sensor_combined`` ``gyro_rad[3]`` (rad/s; ``gyro_rad_s`` before PX4
  1.6) at ``timestamp`` and ``accelerometer_m_s2[3]`` (specific force, m/s²: z ≈ −9.81
  at rest) at ``timestamp + accelerometer_timestamp_relative`` (µs; 0x7fffffff marks no
  accelerometer sample), the primary IMU's samples averaged over each integration
  interval (IMU_INTEG_RATE, PX4 1.11 on: no low-pass); ``vehicle_angular_velocity``
  ``xyz[3]`` (rad/s) and ``vehicle_acceleration`` ``xyz[3]`` (m/s², specific force),
  bias-corrected and low-passed at IMU_GYRO_CUTOFF / IMU_ACCEL_CUTOFF (Hz), at
  ``timestamp_sample``. Of each sensor the faster of the two is read, sensor_combined
  on equal rates. The IMU's position is EKF2_IMU_POS_X/Y/Z (m, body FRD, relative to the
  centre of gravity), from the log's parameters.

Rates (``src/modules/logger/logged_topics.cpp``): ``vehicle_status`` at 2 Hz and on
change, ``vehicle_local_position`` at 10 Hz (the default 100 ms interval),
``vehicle_attitude``, ``esc_status`` and ``actuator_motors`` at full rate with the
high-rate profile (SDLOG_PROFILE) a system-identification flight uses. Otherwise PX4 often
logs ``esc_status`` at 4 Hz: measured rpm is read when sampled at least every
`RPM_USABLE_PERIOD` s, or when no commanded output is logged at least twice as often;
otherwise the commanded outputs carry more information about the rotor speeds between the
rpm samples, and a note says which input was used and why.

Multi-instance topics: the pose topics are read from instance 0, PX4's primary (a
second ``vehicle_local_position`` or odometry instance is another estimator's or
sensor's, never mixed in). Of several ``esc_status`` instances the one with the most
ESCs reporting rpm is read; of ``actuator_motors`` the one with the most motors; of
``actuator_outputs`` (one instance per output driver: PWM main, AUX, DShot, UAVCAN) the
one whose outputs move most, i.e. the one driving the motors, lowest instance on ties.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from mavsysid.formats.bounded_parse import import_parser, parsing
from mavsysid.formats.motor_curve import (
    check_pwm_outputs,
    describe_curve,
    on_battery,
    pwm_curve_caveat,
    rotor_speed_from_pwm,
    rotor_speed_from_throttle,
)
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

from mavsysid.errors import LogFormatError

__all__ = ["ARMING_STATE_ARMED", "ESC_SLOTS", "MOTOR_SLOTS", "NAVIGATION_STATES", "PX4_TOPICS",
           "RPM_USABLE_PERIOD", "ULOG_MAGIC", "Row", "flattened_fields", "read_ulog",
           "read_ulog_modes", "write_ulog"]

#: The file header's magic bytes, then version 1.
ULOG_MAGIC = b"ULog\x01\x12\x35"
_VERSION = 1

_CODES = {"int8_t": "b", "uint8_t": "B", "int16_t": "h", "uint16_t": "H", "int32_t": "i",
          "uint32_t": "I", "int64_t": "q", "uint64_t": "Q", "float": "f", "double": "d",
          "bool": "?", "char": "B"}  # char as its byte value

#: Topic rows: flattened field name → value.
Row = Mapping[str, float]

#: vehicle_status.nav_state values of the modes mavsysid flies in (msg/VehicleStatus.msg).
NAVIGATION_STATES: dict[str, int] = {"MANUAL": 0, "POSCTL": 2, "AUTO_LOITER": 4, "OFFBOARD": 14,
                                     "AUTO_TAKEOFF": 17, "AUTO_LAND": 18}
#: vehicle_status.arming_state of an armed vehicle.
ARMING_STATE_ARMED = 2
#: ESC reports in esc_status, motor slots in actuator_motors.
ESC_SLOTS, MOTOR_SLOTS = 8, 12

#: The topics of a simulated flight, as PX4 defines them (subsets of PX4's fields; readers
#: find fields by name).
PX4_TOPICS: dict[str, str] = {
    "vehicle_status": "uint64_t timestamp;uint64_t nav_state_timestamp;uint8_t nav_state;"
                      "uint8_t arming_state;",
    "vehicle_local_position": "uint64_t timestamp;uint64_t timestamp_sample;bool xy_valid;"
                              "bool z_valid;float x;float y;float z;float vx;float vy;"
                              "float vz;float heading;",
    "vehicle_attitude": "uint64_t timestamp;uint64_t timestamp_sample;float[4] q;",
    "vehicle_mocap_odometry": "uint64_t timestamp;uint64_t timestamp_sample;"
                              "uint8_t pose_frame;float[3] position;float[4] q;",
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;float esc_voltage;float esc_current;"
                  "uint8_t esc_address;",
    "esc_status": "uint64_t timestamp;uint16_t counter;uint8_t esc_count;"
                  "uint8_t esc_connectiontype;esc_report[8] esc;",
    "actuator_motors": "uint64_t timestamp;uint64_t timestamp_sample;"
                       "uint16_t reversible_flags;float[12] control;",
    "sensor_combined": "uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;"
                       "int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;"
                       "uint32_t accelerometer_integral_dt;uint8_t accelerometer_clipping;"
                       "uint8_t gyro_clipping;",
}

#: Longest median sample period of esc_status rpm that is used in preference to motor
#: outputs logged at least twice as often, s. A multirotor's rotor speeds change within
#: tens of ms in a manoeuvre; at 10 Hz measured rpm still resolves the motion the
#: estimator relies on, at 4 Hz the commands between the samples say more.
RPM_USABLE_PERIOD = 0.1
#: PX4 OutputFunction values of Motor1 … Motor12 (esc_report.actuator_function).
_MOTOR_FUNCTIONS = range(101, 113)
#: actuator_motors controls smaller than this are a stopped motor's 0 with float noise.
_STOPPED_CONTROL = 1e-6

_ODOMETRY = ("vehicle_mocap_odometry", "vehicle_visual_odometry")
_IMU_TOPICS = ("sensor_combined", "vehicle_angular_velocity", "vehicle_acceleration")
_TOPICS = [*_ODOMETRY, "vehicle_local_position", "vehicle_attitude", "esc_status",
           "actuator_motors", "actuator_outputs", "battery_status", *_IMU_TOPICS]
#: accelerometer_timestamp_relative of a sensor_combined sample without accelerometer data
#: (sensor_combined_s::RELATIVE_TIMESTAMP_INVALID).
_RELATIVE_INVALID = 0x7FFFFFFF
_POSE_HINT = ("no vehicle_mocap_odometry or vehicle_visual_odometry, nor "
              "vehicle_local_position with vehicle_attitude")

_Topic = dict[str, np.ndarray]
#: Each topic's instances: topic name → {multi_id: field name → array}, non-empty only.
_Instances = dict[str, dict[int, _Topic]]
#: The log's parameters: the initial values, then each change logged in the flight.
_Parameters = dict[str, float]


# --- writing -----------------------------------------------------------------------------


def _message(kind: str, payload: bytes) -> bytes:
    """One ULog message: uint16 payload size, uint8 type, payload."""
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def flattened_fields(name: str, formats: Mapping[str, str],
                     prefix: str = "") -> list[tuple[str, str]]:
    """The flattened (field name, struct code) of a format, nested types expanded.

    Parameters
    ----------
    name : str
        The type whose fields to list.
    formats : mapping of str to str
        Every type name → its fields, ``"type name;"`` items.
    prefix : str
        Prepended to every field name (used for nested types).

    Returns
    -------
    list of (str, str)
        Field names as pyulog reports them (arrays as ``f[i]``, nested as ``a[i].f``)
        and their `struct` codes, in payload order.
    """
    out = []
    for item in filter(None, formats[name].split(";")):
        kind, field = item.strip().split(" ")
        size = int(kind[kind.index("[") + 1:-1]) if "[" in kind else 0
        kind = kind.split("[")[0]
        names = [f"{field}[{i}]" for i in range(size)] if size else [field]
        for n in names:
            if kind in _CODES:
                out.append((prefix + n, _CODES[kind]))
            else:
                out += flattened_fields(kind, formats, f"{prefix}{n}.")
    return out


def _info(key: str, value: str) -> bytes:
    """An ``I`` message with a string value."""
    encoded = value.encode()
    field = f"char[{len(encoded)}] {key}".encode()
    return _message("I", struct.pack("<B", len(field)) + field + encoded)


def _parameter(name: str, value: float | int) -> bytes:
    """A ``P`` message: an int32_t parameter for an int, else a float one."""
    if isinstance(value, int) and not isinstance(value, bool):
        key, packed = f"int32_t {name}", struct.pack("<i", value)
    else:
        key, packed = f"float {name}", struct.pack("<f", float(value))
    return _message("P", struct.pack("<B", len(key)) + key.encode() + packed)


def write_ulog(path: Path, formats: Mapping[str, str],
               topics: Mapping[str | tuple[str, int], Sequence[Row]],
               info: Mapping[str, str] | None = None, start_us: int = 0,
               parameters: Mapping[str, float | int] | None = None) -> None:
    """Write a ULog file.

    Parameters
    ----------
    path : Path
        The ``.ulg`` file to write (replaced if present).
    formats : mapping of str to str
        Every type name (logged or nested) → its fields, ``"uint64_t timestamp;..."``.
    topics : mapping of str or (str, int) to sequence of mapping
        Logged topics: type name, or (type name, multi_id) for an instance other than 0,
        → rows of flattened field values (missing fields are 0). Rows are written in the
        given order, topic after topic: pyulog needs no global time order, and tests of
        out-of-order timestamps need them kept.
    info : mapping of str to str, optional
        ``I`` messages, e.g. ``{"sys_name": "PX4", "ver_sw": "v1.15.0"}``.
    start_us : int
        The header's timestamp, µs.
    parameters : mapping of str to float or int, optional
        The parameters at the log's start (``P`` messages; an int is written as PX4's
        int32 parameters are, a float as a float one), e.g. ``{"EKF2_IMU_POS_X": 0.05}``.

    Raises
    ------
    KeyError
        A topic, or a nested type, without a format.
    struct.error
        A value that does not fit its field type.
    """
    out = bytearray(ULOG_MAGIC + bytes([_VERSION]) + struct.pack("<Q", start_us))
    # Flag bits: no compatible or incompatible flags, no appended data offsets.
    out += _message("B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    for key, value in (info or {}).items():
        out += _info(key, value)
    for name, value in (parameters or {}).items():
        out += _parameter(name, value)
    for name, fields in formats.items():
        out += _message("F", f"{name}:{fields}".encode())
    for msg_id, (key, rows) in enumerate(topics.items()):
        name, multi_id = (key, 0) if isinstance(key, str) else key
        out += _message("A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        fields = flattened_fields(name, formats)
        layout = struct.Struct("<H" + "".join(code for _, code in fields))
        for row in rows:
            out += _message("D", layout.pack(msg_id, *(row.get(n, 0) for n, _ in fields)))
    Path(path).write_bytes(bytes(out))


# --- reading -----------------------------------------------------------------------------


def _load(path: Path) -> tuple[_Instances, _Parameters, list[str]]:
    """Every non-empty instance of each topic used here; the parameters; warnings."""
    ULog = import_parser("pyulog", path).ULog
    with parsing(path, "a PX4 ULog file"):
        ulog = ULog(str(path), message_name_filter_list=_TOPICS)
        parameters = {str(k): float(v) for k, v in ulog.initial_parameters.items()}
        parameters.update({str(k): float(v) for _, k, v in ulog.changed_parameters})
    topics: _Instances = {}
    for d in ulog.data_list:
        if d.data["timestamp"].size:
            topics.setdefault(d.name, {})[int(d.multi_id)] = d.data
    notes = [f"{path}: pyulog found the file corrupt in places and skipped the damaged "
             "parts"] if ulog.file_corruption else []
    return topics, parameters, notes


def _primary(topics: _Instances, name: str) -> _Topic | None:
    """Instance 0 of a topic (PX4's primary), else its lowest instance; None if absent."""
    instances = topics.get(name)
    return instances[min(instances)] if instances else None


def _period(t: np.ndarray) -> float:
    """Median sample period, s (inf for fewer than 2 samples)."""
    return float(np.median(np.diff(np.sort(t)))) if t.size > 1 else np.inf


def _time(topic: _Topic) -> np.ndarray:
    """Sample times, s: timestamp_sample where set, else timestamp (both µs)."""
    stamp = topic["timestamp"].astype(float)
    if "timestamp_sample" in topic:
        sample = topic["timestamp_sample"].astype(float)
        stamp = np.where(sample > 0.0, sample, stamp)
    return stamp * 1e-6


def _columns(topic: _Topic, names: list[str]) -> np.ndarray:
    return np.column_stack([topic[n].astype(float) for n in names])


def _pose(topics: _Instances) -> tuple[Series | None, Series | None, Series | None,
                                     PoseSource]:
    """Odometry pose, else local position and attitude (NED/FRD); the pose's origin."""
    for name in _ODOMETRY:
        odometry = _primary(topics, name)
        if odometry is None:
            continue
        fields = ([f"position[{i}]" for i in range(3)] if "position[0]" in odometry
                  else ["x", "y", "z"])
        p = _columns(odometry, fields)
        q = _columns(odometry, [f"q[{i}]" for i in range(4)])
        pose = Series(_time(odometry), np.column_stack([p, q]), name)
        return pose, None, None, "motion_capture"
    local = _primary(topics, "vehicle_local_position")
    attitude = _primary(topics, "vehicle_attitude")
    if local is None or attitude is None:
        return None, None, None, "autopilot"
    position = Series(_time(local), _columns(local, ["x", "y", "z"]), "vehicle_local_position")
    q = Series(_time(attitude), _columns(attitude, [f"q[{i}]" for i in range(4)]),
               "vehicle_attitude")
    return None, position, q, "autopilot"


def _motor_escs(esc: _Topic) -> list[int]:
    """Indices of the ESCs that drive motors, in motor order."""
    count = int(esc["esc_count"].max())
    functions = {i: int(esc[f"esc[{i}].actuator_function"].max()) for i in range(count)
                 if f"esc[{i}].actuator_function" in esc}
    motors = {f: i for i, f in functions.items() if f in _MOTOR_FUNCTIONS}
    if motors:
        return [motors[f] for f in sorted(motors)]
    return list(range(count))


def _esc(topics: _Instances) -> Series | None:
    """esc_status rpm of the motor ESCs of the instance with most ESCs reporting, rad/s."""
    best, best_count = None, 0
    for _, esc in sorted(topics.get("esc_status", {}).items()):
        escs = _motor_escs(esc)
        # Reported ESC speeds are magnitudes; the spin direction is the config's.
        rpm = np.abs(_columns(esc, [f"esc[{i}].esc_rpm" for i in escs])) if escs else None
        reporting = int((rpm > 0.0).any(axis=0).sum()) if rpm is not None else 0
        if rpm is not None and (best is None or reporting > best_count):
            best = Series(_time(esc), rpm * RPM_TO_RAD_S, "esc_status rpm")
            best_count = reporting
    return best


def _motor_control(motors: _Topic) -> np.ndarray:
    """actuator_motors controls of the motors used (leading columns not NaN throughout)."""
    names = sorted((n for n in motors if n.startswith("control[")), key=lambda n: int(n[8:-1]))
    control = _columns(motors, names)
    used = ~np.isnan(control).all(axis=0)
    count = int(np.argmin(used)) if not used.all() else len(names)
    return control[:, :count]


def _motor_commands(topics: _Instances) -> MotorOutputs | None:
    """actuator_motors relative thrust of the instance with the most motors, as logged."""
    found = [(_motor_control(m), m) for _, m in sorted(topics.get("actuator_motors", {}).items())]
    if not found:
        return None
    # The instance with the most motors; the first of equals.
    control, motors = max(found, key=lambda pair: pair[0].shape[1])
    if not control.shape[1]:
        return None
    return MotorOutputs(Series(_time(motors), control, "actuator_motors"), "normalised")


def _motors(commands: MotorOutputs, vehicle: VehicleConfig) -> Series:
    """actuator_motors relative thrust → n = n_max · sqrt(control), rad/s."""
    thrust = np.nan_to_num(commands.series.values, nan=0.0)  # NaN: motor stopped
    # PX4 logs a disarmed motor as 0 give or take float noise (1e-10): stopped too.
    thrust[np.abs(thrust) < _STOPPED_CONTROL] = 0.0
    speeds = rotor_speed_from_throttle(thrust, vehicle.limits.rotor_speed_max, thrust_expo=0.0)
    return Series(commands.series.t, speeds, "actuator_motors")


def _driving_outputs(topics: _Instances) -> _Topic | None:
    """The actuator_outputs instance whose outputs move most (the motors'); lowest on ties."""
    best, spread = None, -1.0
    for _, outputs in sorted(topics.get("actuator_outputs", {}).items()):
        used = [f"output[{i}]" for i in range(int(outputs["noutputs"].max()))]
        moved = float(np.ptp(_columns(outputs, used), axis=0).sum()) if used else 0.0
        if moved > spread:
            best, spread = outputs, moved
    return best


def _pwm_outputs(topics: _Instances) -> MotorOutputs | None:
    """actuator_outputs of outputs 1..k that drive motors (µs, as PX4's PWM driver logs)."""
    outputs = _driving_outputs(topics)
    if outputs is None:
        return None
    slots = _columns(outputs, [f"output[{i}]" for i in range(int(outputs["noutputs"].max()))])
    count = motor_output_count(slots)
    if not count:
        return None
    return MotorOutputs(Series(_time(outputs), slots[:, :count], "actuator_outputs PWM"), "pwm")


def _motor_outputs(topics: _Instances) -> MotorOutputs | None:
    """The motor outputs as logged: actuator_motors, else actuator_outputs."""
    commands = _motor_commands(topics)
    return commands if commands is not None else _pwm_outputs(topics)


def _commanded(outputs: MotorOutputs | None,
               vehicle: VehicleConfig) -> tuple[Series, str] | None:
    """The commanded rotor speeds (actuator_motors, else actuator_outputs) and their note."""
    if outputs is None:
        return None
    if outputs.kind == "normalised":
        return _motors(outputs, vehicle), (f"actuator_motors thrust commands through "
                                           f"{describe_curve(vehicle, pwm=False)}: commanded, "
                                           "not measured")
    speeds = rotor_speed_from_pwm(outputs.series.values, vehicle)
    return (Series(outputs.series.t, speeds, "actuator_outputs PWM"),
            f"actuator_outputs PWM {pwm_curve_caveat(vehicle)}")


def _checked(path: Path, outputs: MotorOutputs, commanded: tuple[Series, str],
             vehicle: VehicleConfig) -> tuple[Series, str]:
    """``commanded``, once PWM outputs are seen to be PWM in the vehicle's range."""
    if outputs.kind == "pwm":
        check_pwm_outputs(outputs.series.values, vehicle, f"{path}: actuator_outputs")
    return commanded


def _battery(topics: _Instances) -> Series | None:
    """battery_status voltage_v (voltage_filtered_v before PX4 1.14), V; None without one."""
    battery = _primary(topics, "battery_status")
    if battery is None:
        return None
    name = next((n for n in ("voltage_v", "voltage_filtered_v") if n in battery), None)
    if name is None:
        return None
    return Series(_time(battery), battery[name].astype(float)[:, None],
                  f"battery_status {name}")


def _on_battery(path: Path, outputs: MotorOutputs, commanded: tuple[Series, str],
                vehicle: VehicleConfig, battery: Series | None
                ) -> tuple[Series, str, list[str]]:
    """The commanded speeds checked (`_checked`) and scaled by the battery (`on_battery`):
    speeds, what they are, and the battery's notes."""
    series, how = _checked(path, outputs, commanded, vehicle)
    series, said = on_battery(series, battery, vehicle, f"{path}: battery_status")
    return series, how, said


def _rotors(path: Path, esc: Series | None, outputs: MotorOutputs | None,
            vehicle: VehicleConfig, battery: Series | None) -> tuple[Series, list[str]]:
    """Rotor speeds, rad/s, the most informative input; a warning when not measured rpm,
    and what the battery voltage did to commanded ones."""
    commanded = _commanded(outputs, vehicle)
    if esc is not None:
        esc_period = _period(esc.t)
        faster = commanded is not None and 2.0 * _period(commanded[0].t) <= esc_period
        if esc_period <= RPM_USABLE_PERIOD or not faster:
            return esc, []
        series, how, said = _on_battery(path, outputs, commanded, vehicle, battery)
        return series, [f"{path}: esc_status rpm sampled only every {esc_period:.3g} s (more "
                        f"than {RPM_USABLE_PERIOD:g} s), {series.label} every "
                        f"{_period(series.t):.3g} s: rotor speeds are {how}", *said]
    if commanded is not None:
        series, how, said = _on_battery(path, outputs, commanded, vehicle, battery)
        return series, [f"{path}: no esc_status rpm; rotor speeds are {how}", *said]
    raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no esc_status, "
                         "actuator_motors or actuator_outputs)")


# --- IMU ---------------------------------------------------------------------------------


def _vector(topic: _Topic, names: tuple[str, ...]) -> np.ndarray | None:
    """The first of the named 3-vector fields the topic has (``name[0..2]``), or None."""
    for name in names:
        if f"{name}[0]" in topic:
            return _columns(topic, [f"{name}[{i}]" for i in range(3)])
    return None


def _combined(topics: _Instances) -> tuple[Series | None, Series | None]:
    """sensor_combined gyro (at ``timestamp``) and accelerometer (at its relative time)."""
    combined = _primary(topics, "sensor_combined")
    if combined is None:
        return None, None
    t = combined["timestamp"].astype(float) * 1e-6
    gyro = _vector(combined, ("gyro_rad", "gyro_rad_s"))
    accel = _vector(combined, ("accelerometer_m_s2",))
    gyro_series = None if gyro is None else Series(t, gyro, "sensor_combined gyro_rad")
    if accel is None:
        return gyro_series, None
    relative = combined.get("accelerometer_timestamp_relative")
    if relative is None:
        return gyro_series, Series(t, accel, "sensor_combined accelerometer_m_s2")
    relative = relative.astype(float)
    valid = relative != _RELATIVE_INVALID
    return gyro_series, Series(t[valid] + relative[valid] * 1e-6, accel[valid],
                               "sensor_combined accelerometer_m_s2")


def _vehicle_vector(topics: _Instances, name: str) -> Series | None:
    """vehicle_angular_velocity / vehicle_acceleration ``xyz`` at ``timestamp_sample``."""
    topic = _primary(topics, name)
    if topic is None or (xyz := _vector(topic, ("xyz",))) is None:
        return None
    return Series(_time(topic), xyz, f"{name} xyz")


def _faster(combined: Series | None, filtered: Series | None, cutoff: str,
            parameters: _Parameters) -> tuple[Series | None, float | None, str | None]:
    """Of one sensor, the faster series (sensor_combined on ties), the cutoff it went
    through (Hz, 0 for none, None unknown) and the parameter that says so."""
    if filtered is not None and (combined is None or _period(filtered.t) < _period(combined.t)):
        return filtered, parameters.get(cutoff), cutoff if cutoff in parameters else None
    if combined is None:
        return None, None, None
    # PX4 1.11 on (IMU_INTEG_RATE) averages raw samples into sensor_combined, no low-pass.
    if "IMU_INTEG_RATE" in parameters:
        return combined, 0.0, "IMU_INTEG_RATE"
    return combined, None, None


def _imu(topics: _Instances, parameters: _Parameters
         ) -> tuple[Series | None, Series | None, ImuFilter | None]:
    """Gyro and accelerometer (module docstring) and the low-pass they went through."""
    gyro_combined, accel_combined = _combined(topics)
    gyro, gyro_cutoff, gyro_said = _faster(
        gyro_combined, _vehicle_vector(topics, "vehicle_angular_velocity"), "IMU_GYRO_CUTOFF",
        parameters)
    accel, accel_cutoff, accel_said = _faster(
        accel_combined, _vehicle_vector(topics, "vehicle_acceleration"), "IMU_ACCEL_CUTOFF",
        parameters)
    said = [name for name in dict.fromkeys((gyro_said, accel_said)) if name is not None]
    if not said:
        return gyro, accel, None
    source = ", ".join(f"parameter {name}" for name in said)
    return gyro, accel, ImuFilter(gyro_cutoff, accel_cutoff, source)


def _imu_position(parameters: _Parameters) -> tuple[float, float, float] | None:
    """EKF2_IMU_POS_X/Y/Z (m, body FRD), when all three are in the log."""
    names = ("EKF2_IMU_POS_X", "EKF2_IMU_POS_Y", "EKF2_IMU_POS_Z")
    if not all(name in parameters for name in names):
        return None
    x, y, z = (parameters[name] for name in names)
    return (x, y, z)


def read_ulog(path: Path, vehicle: VehicleConfig) -> ParsedLog:
    """Read the pose, rotor speeds, motor outputs and IMU of a PX4 ULog file.

    Parameters
    ----------
    path : Path
        The ``.ulg`` file.
    vehicle : VehicleConfig
        The vehicle: its maximum rotor speed and motor curve (for logs with motor outputs
        only).

    Returns
    -------
    ParsedLog
        NED/FRD, rad/s, m/s², PX4's motor numbering, on PX4's clock (s since boot).

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    topics, parameters, notes = _load(path)
    with parsing(path, "a PX4 ULog file with the usual topic fields"):
        pose, position, attitude, pose_source = _pose(topics)
        esc, outputs = _esc(topics), _motor_outputs(topics)
        rotors, curve = _rotors(path, esc, outputs, vehicle, _battery(topics))
        gyro, accel, imu_filter = _imu(topics, parameters)
    return ParsedLog(source=str(path), pose=pose, position=position, attitude=attitude,
                     pose_source=pose_source, pose_hint=_POSE_HINT, rotors=(rotors,),
                     notes=tuple(notes), rotor_notes=tuple(curve), gyro=gyro, accel=accel,
                     imu_position=_imu_position(parameters), imu_filter=imu_filter,
                     motor_outputs=outputs, esc_speeds=() if esc is None else (esc,))


def read_ulog_modes(path: Path) -> ModeChanges | None:
    """PX4's navigation states over a ULog (``vehicle_status.nav_state``); None without.

    Parameters
    ----------
    path : Path
        The ``.ulg`` file.

    Returns
    -------
    ModeChanges or None
        Mode changes at ``vehicle_status`` times, s since boot, named as in
        `NAVIGATION_STATES` (others ``"nav_state N"``), until the log's last timestamp.
    """
    ULog = import_parser("pyulog", path).ULog
    names = {value: name for name, value in NAVIGATION_STATES.items()}
    with parsing(path, "a PX4 ULog"):
        ulog = ULog(str(path), message_name_filter_list=["vehicle_status"])
        data = [d for d in ulog.data_list if d.name == "vehicle_status"]
        if not data or "nav_state" not in data[0].data:
            return None
        t = data[0].data["timestamp"] * 1e-6
        modes = tuple(names.get(int(n), f"nav_state {int(n)}")
                      for n in data[0].data["nav_state"])
        end = ulog.last_timestamp * 1e-6
    return ModeChanges(t=t, modes=modes, events=True, end=end)
