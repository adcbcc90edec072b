"""PX4 ULog files (``.ulg``), read with pyulog.

Pose: ``vehicle_mocap_odometry``, else ``vehicle_visual_odometry`` (motion capture or
vision forwarded to PX4: ``position[3]`` or, before PX4 1.14, ``x, y, z``, and ``q``
[w, x, y, z]), else ``vehicle_local_position`` (x, y, z) with ``vehicle_attitude`` (q),
the autopilot's estimate. PX4 frames are NED/FRD; an odometry ``pose_frame`` of FRD (a
z-down world frame with arbitrary heading) is taken as NED, which only turns the world
frame about the vertical, which the model does not see. Times are ``timestamp_sample``
(the measurement time) where the topic has it, else ``timestamp``; µs since boot → s.

Rotor speeds: ``esc_status`` ``esc[i].esc_rpm``, measured. The ESCs are those whose
``actuator_function`` is a motor (101 = Motor1 … 112), in motor order, where the log has
that field; else ESCs 0..``esc_count`` − 1 (ESC i is motor output i + 1, put into the
config's rotor order by `mavsysid.estimation.readers.motor_outputs`).
Measured rpm is used when sampled at least every `RPM_USABLE_PERIOD` s, or when no
commanded output is logged at least twice as often; otherwise (PX4 often logs
``esc_status`` at 4 Hz) the commanded outputs carry more information about the rotor
speeds between the rpm samples, and a warning says which input was used and why. Every
input is interpolated to the pose times, and what that costs is modelled as added
uncertainty (`mavsysid.estimation.input_noise`), whatever the rate.

Motor outputs: ``actuator_motors`` ``control[i]`` is relative *thrust* (PX4 applies
THR_MDL_FAC after it, in the output driver), so n = rotor_speed_max · sqrt(control) — the
motor curve with thrust_expo 0; NaN there means a stopped motor (n = 0), and a column
that is NaN throughout an unused one. Else ``actuator_outputs`` ``output[i]`` (taken as
PWM in µs) through the vehicle's `[motor]` curve.

Multi-instance topics: the pose topics are read from instance 0, PX4's primary (a
second ``vehicle_local_position`` or odometry instance is another estimator's or
sensor's, never mixed in). Of several ``esc_status`` instances the one with the most
ESCs reporting rpm is read; of ``actuator_motors`` the one with the most motors; of
``actuator_outputs`` (one instance per output driver: PWM main, AUX, DShot, UAVCAN) the
one whose outputs move most, i.e. the one driving the motors, lowest instance on ties.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mavsysid.estimation.readers.guard import import_parser, parsing
from mavsysid.estimation.readers.motor_curve import (
    describe_curve,
    rotor_speed_from_pwm,
    rotor_speed_from_throttle,
)
from mavsysid.estimation.readers.motor_outputs import motor_output_count, rotors_in_config_order
from mavsysid.estimation.readers.streams import LogStreams, PoseSource, Series, combine_pose
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import ned_to_enu, quaternion_ned_to_enu

from mavsysid.errors import LogFormatError

__all__ = ["RPM_USABLE_PERIOD", "read_ulog"]

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
_TOPICS = [*_ODOMETRY, "vehicle_local_position", "vehicle_attitude", "esc_status",
           "actuator_motors", "actuator_outputs"]
_POSE_HINT = ("no vehicle_mocap_odometry or vehicle_visual_odometry, nor "
              "vehicle_local_position with vehicle_attitude")

Topic = dict[str, np.ndarray]
#: Each topic's instances: topic name → {multi_id: field name → array}, non-empty only.
Instances = dict[str, dict[int, Topic]]


def _load(path: Path) -> tuple[Instances, list[str]]:
    """Every non-empty instance of each topic used here; and warnings."""
    ULog = import_parser("pyulog", path).ULog
    with parsing(path, "a PX4 ULog file"):
        ulog = ULog(str(path), message_name_filter_list=_TOPICS)
    topics: Instances = {}
    for d in ulog.data_list:
        if d.data["timestamp"].size:
            topics.setdefault(d.name, {})[int(d.multi_id)] = d.data
    notes = [f"{path}: pyulog found the file corrupt in places and skipped the damaged "
             "parts"] if ulog.file_corruption else []
    return topics, notes


def _primary(topics: Instances, name: str) -> Topic | None:
    """Instance 0 of a topic (PX4's primary), else its lowest instance; None if absent."""
    instances = topics.get(name)
    return instances[min(instances)] if instances else None


def _period(t: np.ndarray) -> float:
    """Median sample period, s (inf for fewer than 2 samples)."""
    return float(np.median(np.diff(np.sort(t)))) if t.size > 1 else np.inf


def _time(topic: Topic) -> np.ndarray:
    """Sample times, s: timestamp_sample where set, else timestamp (both µs)."""
    stamp = topic["timestamp"].astype(float)
    if "timestamp_sample" in topic:
        sample = topic["timestamp_sample"].astype(float)
        stamp = np.where(sample > 0.0, sample, stamp)
    return stamp * 1e-6


def _columns(topic: Topic, names: list[str]) -> np.ndarray:
    return np.column_stack([topic[n].astype(float) for n in names])


def _pose(path: Path, topics: Instances) -> tuple[Series | None, PoseSource, list[str]]:
    """The pose series, its origin and warnings from cleaning it."""
    for name in _ODOMETRY:
        odometry = _primary(topics, name)
        if odometry is None:
            continue
        fields = ([f"position[{i}]" for i in range(3)] if "position[0]" in odometry
                  else ["x", "y", "z"])
        p = _columns(odometry, fields)
        q = _columns(odometry, [f"q[{i}]" for i in range(4)])
        values = np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)])
        return Series(_time(odometry), values, name), "motion_capture", []
    local = _primary(topics, "vehicle_local_position")
    attitude = _primary(topics, "vehicle_attitude")
    if local is None or attitude is None:
        return None, "autopilot", []
    position = Series(_time(local), _columns(local, ["x", "y", "z"]), "vehicle_local_position")
    q = Series(_time(attitude), _columns(attitude, [f"q[{i}]" for i in range(4)]),
               "vehicle_attitude")
    pose, notes = combine_pose(str(path), position, q)
    return pose, "autopilot", notes


def _motor_escs(esc: Topic) -> list[int]:
    """Indices of the ESCs that drive motors, in motor order."""
    count = int(esc["esc_count"].max())
    functions = {i: int(esc[f"esc[{i}].actuator_function"].max()) for i in range(count)
                 if f"esc[{i}].actuator_function" in esc}
    motors = {f: i for i, f in functions.items() if f in _MOTOR_FUNCTIONS}
    if motors:
        return [motors[f] for f in sorted(motors)]
    return list(range(count))


def _esc(topics: Instances) -> Series | None:
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


def _motor_control(motors: Topic) -> np.ndarray:
    """actuator_motors controls of the motors used (leading columns not NaN throughout)."""
    names = sorted((n for n in motors if n.startswith("control[")), key=lambda n: int(n[8:-1]))
    control = _columns(motors, names)
    used = ~np.isnan(control).all(axis=0)
    count = int(np.argmin(used)) if not used.all() else len(names)
    return control[:, :count]


def _motors(topics: Instances, vehicle: VehicleConfig) -> Series | None:
    """actuator_motors relative thrust → n = n_max · sqrt(control), rad/s."""
    found = [(_motor_control(m), m) for _, m in sorted(topics.get("actuator_motors", {}).items())]
    if not found:
        return None
    # The instance with the most motors; the first of equals.
    control, motors = max(found, key=lambda pair: pair[0].shape[1])
    if not control.shape[1]:
        return None
    thrust = np.nan_to_num(control, nan=0.0)  # NaN: motor stopped
    # PX4 logs a disarmed motor as 0 give or take float noise (1e-10): stopped too.
    thrust[np.abs(thrust) < _STOPPED_CONTROL] = 0.0
    speeds = rotor_speed_from_throttle(thrust, vehicle.limits.rotor_speed_max, thrust_expo=0.0)
    return Series(_time(motors), speeds, "actuator_motors")


def _driving_outputs(topics: Instances) -> Topic | None:
    """The actuator_outputs instance whose outputs move most (the motors'); lowest on ties."""
    best, spread = None, -1.0
    for _, outputs in sorted(topics.get("actuator_outputs", {}).items()):
        used = [f"output[{i}]" for i in range(int(outputs["noutputs"].max()))]
        moved = float(np.ptp(_columns(outputs, used), axis=0).sum()) if used else 0.0
        if moved > spread:
            best, spread = outputs, moved
    return best


def _outputs(topics: Instances, vehicle: VehicleConfig) -> Series | None:
    """actuator_outputs PWM of outputs 1..k through the vehicle's motor curve, rad/s."""
    outputs = _driving_outputs(topics)
    if outputs is None:
        return None
    slots = _columns(outputs, [f"output[{i}]" for i in range(int(outputs["noutputs"].max()))])
    count = motor_output_count(slots)
    if not count:
        return None
    pwm = slots[:, :count]
    return Series(_time(outputs), rotor_speed_from_pwm(pwm, vehicle), "actuator_outputs PWM")


def _commanded(path: Path, topics: Instances,
               vehicle: VehicleConfig) -> tuple[Series, str] | None:
    """The commanded rotor speeds (actuator_motors, else actuator_outputs) and their note."""
    if (motors := _motors(topics, vehicle)) is not None:
        return motors, (f"actuator_motors thrust commands through "
                        f"{describe_curve(vehicle, pwm=False)}: commanded, not measured")
    if (outputs := _outputs(topics, vehicle)) is not None:
        return outputs, (f"actuator_outputs PWM through the motor curve "
                         f"{describe_curve(vehicle, pwm=True)}: commanded, not measured, and "
                         "only as right as the [motor] keys of the vehicle config")
    return None


def _rotors(path: Path, topics: Instances,
            vehicle: VehicleConfig) -> tuple[Series, list[str]]:
    """Rotor speeds, rad/s, the most informative input; a warning when not measured rpm."""
    esc = _esc(topics)
    commanded = _commanded(path, topics, vehicle)
    if esc is not None:
        esc_period = _period(esc.t)
        faster = commanded is not None and 2.0 * _period(commanded[0].t) <= esc_period
        if esc_period <= RPM_USABLE_PERIOD or not faster:
            return esc, []
        series, how = commanded
        return series, [f"{path}: esc_status rpm sampled only every {esc_period:.3g} s (more "
                        f"than {RPM_USABLE_PERIOD:g} s), {series.label} every "
                        f"{_period(series.t):.3g} s: rotor speeds are {how}"]
    if commanded is not None:
        series, how = commanded
        return series, [f"{path}: no esc_status rpm; rotor speeds are {how}"]
    raise LogFormatError(f"{path}: no rotor speeds or motor outputs in {path} (no esc_status, "
                         "actuator_motors or actuator_outputs)")


def read_ulog(path: Path, vehicle: VehicleConfig) -> LogStreams:
    """Read the pose and rotor speeds of a PX4 ULog file.

    Parameters
    ----------
    path : Path
        The ``.ulg`` file.
    vehicle : VehicleConfig
        The vehicle: its rotor count, maximum rotor speed and motor curve (for logs with
        motor outputs only).

    Returns
    -------
    LogStreams
        In ENU/FLU and rad/s, on PX4's clock (s since boot).

    Raises
    ------
    LogFormatError
        An unreadable file, or neither ESC rpm nor motor outputs.
    """
    topics, notes = _load(path)
    with parsing(path, "a PX4 ULog file with the usual topic fields"):
        pose, pose_source, more = _pose(path, topics)
        rotors, curve = _rotors(path, topics, vehicle)
    ordered, order_notes = rotors_in_config_order(str(path), (rotors,), vehicle)
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source, rotors=ordered,
                      warnings=(*notes, *more, *curve, *order_notes), pose_hint=_POSE_HINT)
