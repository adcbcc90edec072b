"""Pre-flight checks of a streamed flight: refuse with the reason, or warn.

Two groups. Before connecting (`check_plan`): the trajectory was made for this vehicle,
every sample of it at 100 Hz lies inside the flight box, and nothing between the samples
leaves the box or exceeds the vehicle's limits (speed, thrust, jerk, yaw rate, continuity;
`mavsysid.flight.ground.trajectory_safety`). After connecting and before
arming (`check_vehicle`): the airframe reported in the HEARTBEAT has the configured
rotor count, the vehicle stands under the box (its climb and its transfer to the start
then stay inside it), it is healthy and disarmed, and the telemetry the estimator needs
arrives fast enough.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsysid.flight.ground.mavlink_link import VehicleState
from mavsysid.flight.ground.trajectory_safety import check_trajectory, flight_limits
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.trajectory import PiecewisePolynomial, Trajectory

from mavsysid.errors import JobFailedError

__all__ = [
    "MAV_TYPE_ROTORS",
    "PreflightReport",
    "check_airframe",
    "check_box",
    "check_health",
    "check_plan",
    "check_rates",
    "check_takeoff_point",
    "check_vehicle",
]

#: Rotor count of the multirotor MAV_TYPEs: QUADROTOR, HEXAROTOR, OCTOROTOR, TRICOPTER,
#: DODECAROTOR.
MAV_TYPE_ROTORS = {2: 4, 13: 6, 14: 8, 15: 3, 29: 12}
_MAV_STATE_NAMES = {5: "CRITICAL", 6: "EMERGENCY", 7: "POWEROFF", 8: "FLIGHT_TERMINATION"}
_AXES = "xyz"


@dataclass(frozen=True)
class PreflightReport:
    """Reasons to refuse the flight and things to warn about (one line each)."""

    refusals: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()

    def __add__(self, other: PreflightReport) -> PreflightReport:
        return PreflightReport(self.refusals + other.refusals, self.warnings + other.warnings)

    def raise_if_refused(self) -> None:
        """Raise `JobFailedError` "flight refused: …" naming every refusal."""
        if self.refusals:
            raise JobFailedError("flight refused: " + "; ".join(self.refusals))


def check_box(trajectory: Trajectory, box: Sequence[float], rate: float = 100.0) -> list[str]:
    """Refusals for samples outside ``box`` = [x_min, y_min, z_min, x_max, y_max, z_max] (m).

    Samples at ``rate`` Hz from 0 to the duration (the end included). One line naming the
    first sample outside and the farthest excursion.
    """
    lo, hi = np.asarray(box[:3], dtype=float), np.asarray(box[3:], dtype=float)
    n = int(np.floor(trajectory.duration * rate + 1e-9)) + 1
    t = np.append(np.arange(n) / rate, trajectory.duration)
    p = trajectory.flat_outputs(t).position
    excess = np.maximum(lo - p, p - hi)  # > 0 outside, per axis
    outside = np.any(excess > 0.0, axis=1)
    if not outside.any():
        return []
    i = int(np.argmax(outside))
    j = int(np.argmax(excess[i]))
    worst = np.unravel_index(int(np.argmax(excess)), excess.shape)
    side = "min" if p[i, j] < lo[j] else "max"
    limit = lo[j] if side == "min" else hi[j]
    shown = ",".join(f"{b:g}" for b in box)
    return [f"the trajectory leaves the box [{shown}] at t = {t[i]:.2f} s "
            f"({_AXES[j]} = {p[i, j]:.3f} m, {_AXES[j]}_{side} {limit:g} m); farthest "
            f"{excess[worst]:.3f} m outside at t = {t[worst[0]]:.2f} s"]


def check_takeoff_point(position: Sequence[float], box: Sequence[float]) -> list[str]:
    """Refusal unless the vehicle stands inside the box's footprint (x, y), m.

    It climbs straight up to the start height and then flies straight to the start: both
    stay inside the (convex) box only if the take-off point is under it.
    """
    x, y = float(position[0]), float(position[1])
    if box[0] <= x <= box[3] and box[1] <= y <= box[4]:
        return []
    return [f"the vehicle is at x = {x:.2f} m, y = {y:.2f} m, outside the box's footprint "
            f"[{box[0]:g}, {box[3]:g}] x [{box[1]:g}, {box[4]:g}] m: take off under the box"]


def check_plan(trajectory: Trajectory, trajectory_vehicle: str, config: VehicleConfig,
               box: Sequence[float], box_source: str = "the box") -> PreflightReport:
    """Checks that need no vehicle: the trajectory's vehicle name, the box, the limits.

    The limits (`check_trajectory`) are checked when the box is not already left, so a
    refusal names one problem; ``box_source`` says whose box it is in the message.
    """
    refusals = []
    if trajectory_vehicle != config.name:
        refusals.append(f"the trajectory was made for vehicle {trajectory_vehicle!r}, "
                        f"not {config.name!r}")
    with np.errstate(all="ignore"):  # a mutated file may overflow; the checks say so
        outside = [f"{line} (box: {box_source})" for line in check_box(trajectory, box)]
    refusals += outside
    if not outside and isinstance(trajectory, PiecewisePolynomial):
        refusals += check_trajectory(trajectory, flight_limits(config, box), box_source)
    return PreflightReport(tuple(refusals))


def check_airframe(config: VehicleConfig, mav_type: int, type_name: str = "") -> list[str]:
    """Refusal if the HEARTBEAT's multirotor type has another rotor count than ``config``."""
    rotors = MAV_TYPE_ROTORS.get(mav_type)
    if rotors is None or rotors == config.rotor_count:
        return []
    return [f"the vehicle reports a {type_name or f'MAV_TYPE {mav_type}'} ({rotors} rotors) "
            f"but {config.name} has {config.rotor_count}"]


def _bit_names(bits: int, names: Mapping[int, str]) -> str:
    found = [names.get(1 << b, f"bit {b}") for b in range(32) if bits & (1 << b)]
    return ", ".join(n.removeprefix("MAV_SYS_STATUS_SENSOR_") for n in found)


def check_health(vehicle: VehicleState, sys_status: Any | None,
                 sensor_names: Mapping[int, str] | None = None) -> PreflightReport:
    """Refusals for an armed or failing vehicle, unhealthy sensors or a low battery.

    ``sys_status`` is the last SYS_STATUS (None: health unknown, a warning);
    ``sensor_names`` maps MAV_SYS_STATUS_SENSOR bits to names.
    """
    refusals, warnings = [], []
    if vehicle.armed:
        refusals.append("the vehicle is already armed; land and disarm it first")
    if vehicle.system_status in _MAV_STATE_NAMES:
        refusals.append(f"the vehicle reports state MAV_STATE_"
                        f"{_MAV_STATE_NAMES[vehicle.system_status]}")
    if sys_status is None:
        warnings.append("no SYS_STATUS from the vehicle: sensor health not checked")
        return PreflightReport(tuple(refusals), tuple(warnings))
    enabled = (sys_status.onboard_control_sensors_enabled
               & sys_status.onboard_control_sensors_present)
    unhealthy = enabled & ~sys_status.onboard_control_sensors_health
    if unhealthy:
        refusals.append(f"unhealthy sensors: {_bit_names(unhealthy, sensor_names or {})}")
    battery = sys_status.battery_remaining
    if 0 <= battery < 30:
        refusals.append(f"battery at {battery} %")
    return PreflightReport(tuple(refusals), tuple(warnings))


def check_rates(achieved: Mapping[str, float], wanted: float, rotor_count: int,
                minimum_pose_rate: float = 5.0) -> PreflightReport:
    """Warn when telemetry the estimator needs comes slower than 90 % of ``wanted`` Hz.

    Slow ESC rpm with the motor outputs (SERVO_OUTPUT_RAW) at the rate is a note of its own:
    ``estimate`` then reads the rotor speeds from the outputs in ``flight.tlog`` through the
    vehicle file's ``[motor]`` curve (commanded, not measured). Refuses when
    LOCAL_POSITION_NED comes slower than ``minimum_pose_rate`` Hz: the streamer could not
    watch the tracking error.
    """
    esc = ["ESC_TELEMETRY_1_TO_4"] + (["ESC_TELEMETRY_5_TO_8"] if rotor_count > 4 else [])
    refusals, slow, warnings = [], [], []
    outputs = achieved.get("SERVO_OUTPUT_RAW", 0.0)
    slow_esc = [f"{n} {achieved.get(n, 0.0):.1f} Hz" for n in esc
                if achieved.get(n, 0.0) < 0.9 * wanted]
    needed = ["LOCAL_POSITION_NED", "ATTITUDE_QUATERNION"]
    if slow_esc and outputs >= 0.9 * wanted:
        warnings.append(f"no ESC rpm at the rate asked for ({', '.join(slow_esc)}): "
                        f"estimate will read the motor outputs (SERVO_OUTPUT_RAW "
                        f"{outputs:.1f} Hz in flight.tlog) through the vehicle file's "
                        "[motor] curve, commanded speeds, not measured ones")
    else:
        needed += esc
    for name in needed:
        rate = achieved.get(name, 0.0)
        if rate < 0.9 * wanted:
            slow.append(f"{name} {rate:.1f} Hz")
    if achieved.get("LOCAL_POSITION_NED", 0.0) < minimum_pose_rate:
        refusals.append(f"LOCAL_POSITION_NED arrives at "
                        f"{achieved.get('LOCAL_POSITION_NED', 0.0):.1f} Hz, below "
                        f"{minimum_pose_rate:g} Hz: cannot watch the tracking error")
    if slow:
        warnings.insert(0, f"telemetry slower than the {wanted:g} Hz asked for "
                        f"({', '.join(slow)}): the pose log will have less information for "
                        "estimation")
    return PreflightReport(tuple(refusals), tuple(warnings))


def check_vehicle(config: VehicleConfig, vehicle: VehicleState, type_name: str,
                  sys_status: Any | None, sensor_names: Mapping[int, str],
                  achieved: Mapping[str, float], wanted_rate: float,
                  position: Sequence[float], box: Sequence[float]) -> PreflightReport:
    """All checks of the connected vehicle (airframe, take-off point, health, rates)."""
    report = PreflightReport(tuple(check_airframe(config, vehicle.mav_type, type_name)
                                   + check_takeoff_point(position, box)))
    return (report + check_health(vehicle, sys_status, sensor_names)
            + check_rates(achieved, wanted_rate, config.rotor_count))
