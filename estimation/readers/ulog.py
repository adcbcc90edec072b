"""PX4 ULog files (``.ulg``), read with pyulog.

Pose: ``vehicle_mocap_odometry``, else ``vehicle_visual_odometry`` (motion capture or
vision forwarded to PX4: ``position[3]`` or, before PX4 1.14, ``x, y, z``, and ``q``
[w, x, y, z]), else ``vehicle_local_position`` (x, y, z) with ``vehicle_attitude`` (q),
the autopilot's estimate. PX4 frames are NED/FRD; an odometry ``pose_frame`` of FRD (a
z-down world frame with arbitrary heading) is taken as NED, which only turns the world
frame about the vertical, which the model does not see. Times are ``timestamp_sample``
(the measurement time) where the topic has it, else ``timestamp``; µs since boot → s.

Rotor speeds: ``esc_status`` ``esc[i].esc_rpm`` for i < ``esc_count`` (ESC i is rotor
i + 1 of the vehicle config), else motor outputs with a warning: ``actuator_motors``
``control[i]`` is relative *thrust* (PX4 applies THR_MDL_FAC after it, in the output
driver), so n = rotor_speed_max · sqrt(control) — the motor curve with thrust_expo 0;
NaN there means a stopped motor (n = 0), and a column that is NaN throughout an unused
one. Else ``actuator_outputs`` ``output[i]`` (instance 0, taken as PWM in µs) through
the vehicle's `[motor]` curve. Only instance 0 of each topic is read.
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
from mavsysid.estimation.readers.streams import LogStreams, PoseSource, Series, combine_pose
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import RPM_TO_RAD_S
from mavsysid.vehicle.frames import ned_to_enu, quaternion_ned_to_enu

from mavsysid.errors import LogFormatError

__all__ = ["read_ulog"]

_ODOMETRY = ("vehicle_mocap_odometry", "vehicle_visual_odometry")
_TOPICS = [*_ODOMETRY, "vehicle_local_position", "vehicle_attitude", "esc_status",
           "actuator_motors", "actuator_outputs"]
_POSE_HINT = ("no vehicle_mocap_odometry or vehicle_visual_odometry, nor "
              "vehicle_local_position with vehicle_attitude")

Topic = dict[str, np.ndarray]


def _load(path: Path) -> tuple[dict[str, Topic], list[str]]:
    """Instance 0 of each topic used here, as field name → array; and warnings."""
    ULog = import_parser("pyulog", path).ULog
    with parsing(path, "a PX4 ULog file"):
        ulog = ULog(str(path), message_name_filter_list=_TOPICS)
    topics = {d.name: d.data for d in ulog.data_list if d.multi_id == 0}
    notes = [f"{path}: pyulog found the file corrupt in places and skipped the damaged "
             "parts"] if ulog.file_corruption else []
    return topics, notes


def _time(topic: Topic) -> np.ndarray:
    """Sample times, s: timestamp_sample where set, else timestamp (both µs)."""
    stamp = topic["timestamp"].astype(float)
    if "timestamp_sample" in topic:
        sample = topic["timestamp_sample"].astype(float)
        stamp = np.where(sample > 0.0, sample, stamp)
    return stamp * 1e-6


def _columns(topic: Topic, names: list[str]) -> np.ndarray:
    return np.column_stack([topic[n].astype(float) for n in names])


def _pose(path: Path, topics: dict[str, Topic]) -> tuple[Series | None, PoseSource, list[str]]:
    """The pose series, its origin and warnings from cleaning it."""
    for name in _ODOMETRY:
        odometry = topics.get(name)
        if odometry is None:
            continue
        fields = ([f"position[{i}]" for i in range(3)] if "position[0]" in odometry
                  else ["x", "y", "z"])
        p = _columns(odometry, fields)
        q = _columns(odometry, [f"q[{i}]" for i in range(4)])
        values = np.column_stack([ned_to_enu(p), quaternion_ned_to_enu(q)])
        return Series(_time(odometry), values, name), "motion_capture", []
    local, attitude = topics.get("vehicle_local_position"), topics.get("vehicle_attitude")
    if local is None or attitude is None:
        return None, "autopilot", []
    position = Series(_time(local), _columns(local, ["x", "y", "z"]), "vehicle_local_position")
    q = Series(_time(attitude), _columns(attitude, [f"q[{i}]" for i in range(4)]),
               "vehicle_attitude")
    pose, notes = combine_pose(str(path), position, q)
    return pose, "autopilot", notes


def _esc(topics: dict[str, Topic]) -> Series | None:
    """esc_status rpm of ESCs 0..esc_count − 1, rad/s."""
    esc = topics.get("esc_status")
    count = int(esc["esc_count"].max()) if esc is not None and esc["timestamp"].size else 0
    if not count:
        return None
    # Reported ESC speeds are magnitudes; the spin direction is the config's.
    rpm = np.abs(_columns(esc, [f"esc[{i}].esc_rpm" for i in range(count)]))
    return Series(_time(esc), rpm * RPM_TO_RAD_S, "esc_status rpm")


def _motors(topics: dict[str, Topic], vehicle: VehicleConfig) -> Series | None:
    """actuator_motors relative thrust → n = n_max · sqrt(control), rad/s."""
    motors = topics.get("actuator_motors")
    if motors is None or not motors["timestamp"].size:
        return None
    names = sorted((n for n in motors if n.startswith("control[")), key=lambda n: int(n[8:-1]))
    control = _columns(motors, names)
    used = ~np.isnan(control).all(axis=0)
    count = int(np.argmin(used)) if not used.all() else len(names)
    if not count:
        return None
    thrust = np.nan_to_num(control[:, :count], nan=0.0)  # NaN: motor stopped
    speeds = rotor_speed_from_throttle(thrust, vehicle.limits.rotor_speed_max, thrust_expo=0.0)
    return Series(_time(motors), speeds, "actuator_motors")


def _outputs(topics: dict[str, Topic], vehicle: VehicleConfig) -> Series | None:
    """actuator_outputs PWM of outputs 1..k through the vehicle's motor curve, rad/s."""
    outputs = topics.get("actuator_outputs")
    if outputs is None or not outputs["timestamp"].size:
        return None
    count = min(int(outputs["noutputs"].max()), vehicle.rotor_count)
    if not count:
        return None
    pwm = _columns(outputs, [f"output[{i}]" for i in range(count)])
    return Series(_time(outputs), rotor_speed_from_pwm(pwm, vehicle), "actuator_outputs PWM")


def _rotors(path: Path, topics: dict[str, Topic],
            vehicle: VehicleConfig) -> tuple[Series, list[str]]:
    """Rotor speeds, rad/s, and a warning when they come from motor outputs."""
    if (esc := _esc(topics)) is not None:
        return esc, []
    if (motors := _motors(topics, vehicle)) is not None:
        return motors, [f"{path}: no esc_status rpm; rotor speeds are actuator_motors thrust "
                        f"commands through {describe_curve(vehicle, pwm=False)}: commanded, "
                        "not measured"]
    if (outputs := _outputs(topics, vehicle)) is not None:
        return outputs, [f"{path}: no esc_status rpm; rotor speeds are actuator_outputs PWM "
                         f"through the motor curve {describe_curve(vehicle, pwm=True)}: "
                         "commanded, not measured, and only as right as the [motor] keys of "
                         "the vehicle config"]
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
    return LogStreams(source=str(path), pose=pose, pose_source=pose_source, rotors=(rotors,),
                      warnings=(*notes, *more, *curve), pose_hint=_POSE_HINT)
