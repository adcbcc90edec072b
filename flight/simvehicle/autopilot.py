"""Autopilot behaviour of the simulated vehicle: modes, arming, takeoff, landing, failsafes.

Two personalities. ArduPilot Copter: starts in STABILIZE; GUIDED takes
SET_POSITION_TARGET_LOCAL_NED (`mavsysid.flight.simvehicle.setpoint_input`), and after GUID_TIMEOUT
without
one drops the velocity/acceleration feed-forward and holds the position target; a
takeoff (NAV_TAKEOFF) only in GUIDED, armed and landed; disarms itself DISARM_DELAY s
after arming without taking off, and on touchdown in LAND. PX4: starts in Hold;
OFFBOARD needs setpoints streaming at > 2 Hz for > 1 s, and falls back to Hold when
none came for COM_OF_LOSS_T (to COM_OBL_RC_ACT's mode); NAV_TAKEOFF switches to Takeoff
and then Hold. Both check their geofence and act on a breach as the real ones do
(`mavsysid.flight.simvehicle.fence`).

With ``land_detector_fails`` (ArduCopter in strong wind, measured on SITL: its land
detector waits for the motors at their lower limit, which the attitude controller fighting
the wind on the ground never lets them reach) a touchdown in LAND is not detected: the
vehicle rests on the ground armed, reports itself still landing, does not disarm itself
and refuses a ground station's disarm unless forced (param2 21196).

Modes that need a position estimate are refused (TEMPORARILY_REJECTED) until the
simulated EKF has one (``--ekf-delay``). STABILIZE/ALT_HOLD/MANUAL/POSCTL have no pilot
here: in the air they hold the position, as a pilot with centred sticks would roughly.
Every decision returns a MAV_RESULT; STATUSTEXT lines go to `events` like the real ones.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES, PX4_MODES, Autopilot, px4_custom_mode
from mavsysid.flight.simvehicle.fence import FenceMonitor, guided_timeout, offboard_loss_modes
from mavsysid.flight.simvehicle.link import mavlink
from mavsysid.flight.simvehicle.params import ParameterTable
from mavsysid.flight.simvehicle.physics import ORIGIN, SimVehicle
from mavsysid.flight.simvehicle.reference import T_POS, T_USE_Z, T_VEL, T_YAW, hold_target
from mavsysid.flight.simvehicle.setpoint_input import SetpointTracker

__all__ = ["ModeSpec", "SimAutopilot"]

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
DENIED = mavlink.MAV_RESULT_DENIED
FAILED = mavlink.MAV_RESULT_FAILED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED

_WARNING = mavlink.MAV_SEVERITY_WARNING
_INFO = mavlink.MAV_SEVERITY_INFO
_TOUCHDOWN_S = 0.1      # ground contact while landing before "landed"
_REST_S = 0.5           # ground contact with the target below ground before "landed"
_ARRIVED_M = 0.1        # takeoff height reached within this
_BRAKE_DECEL = 7.5      # m/s², ArduCopter's BRAKE_MODE_DECEL_RATE (mode_brake.cpp)
_STOPS_MOTORS = ("DISARM", "TERMINATE")


@dataclass(frozen=True)
class ModeSpec:
    """What a flight mode does here.

    Attributes
    ----------
    kind : str
        ``manual``, ``hold``, ``guided``, ``land``, ``rtl`` or ``takeoff``.
    needs_position : bool
        Refused until the EKF has a position.
    allows_arming : bool
    """

    kind: str
    needs_position: bool
    allows_arming: bool


_ARDUPILOT = {
    ARDUCOPTER_MODES["STABILIZE"]: ModeSpec("manual", False, True),
    ARDUCOPTER_MODES["ALT_HOLD"]: ModeSpec("manual", False, True),
    ARDUCOPTER_MODES["GUIDED"]: ModeSpec("guided", True, True),
    ARDUCOPTER_MODES["LOITER"]: ModeSpec("hold", True, True),
    ARDUCOPTER_MODES["POSHOLD"]: ModeSpec("hold", True, True),
    ARDUCOPTER_MODES["BRAKE"]: ModeSpec("hold", True, False),
    ARDUCOPTER_MODES["RTL"]: ModeSpec("rtl", True, False),
    ARDUCOPTER_MODES["LAND"]: ModeSpec("land", False, False),
}
_PX4_RTL = px4_custom_mode(4, 5)
_PX4 = {
    PX4_MODES["MANUAL"]: ModeSpec("manual", False, True),
    PX4_MODES["POSCTL"]: ModeSpec("manual", True, True),
    PX4_MODES["TAKEOFF"]: ModeSpec("takeoff", True, True),
    PX4_MODES["HOLD"]: ModeSpec("hold", True, True),
    PX4_MODES["LAND"]: ModeSpec("land", True, False),
    PX4_MODES["OFFBOARD"]: ModeSpec("guided", True, True),
    _PX4_RTL: ModeSpec("rtl", True, False),
}


class SimAutopilot:
    """The flight-mode logic on top of a `SimVehicle`.

    Parameters
    ----------
    vehicle : SimVehicle
    autopilot : Autopilot
    params : ParameterTable
        This autopilot's parameters (read live; limits follow changes).
    ekf_delay : float
        Sim seconds before a position estimate exists.
    deny_arm : bool
        Refuse every arming request (a simulated pre-arm failure).
    land_detector_fails : bool
        A touchdown in LAND goes undetected (see the module docstring).
    """

    def __init__(self, vehicle: SimVehicle, autopilot: Autopilot, params: ParameterTable,
                 ekf_delay: float = 2.0, deny_arm: bool = False,
                 land_detector_fails: bool = False) -> None:
        self.vehicle = vehicle
        self.autopilot = autopilot
        self.params = params
        self.ekf_delay = float(ekf_delay)
        self.deny_arm = deny_arm
        self.land_detector_fails = land_detector_fails
        #: On the ground after a LAND whose touchdown went undetected.
        self.land_undetected = False
        self.ardupilot = autopilot is Autopilot.ARDUPILOT
        self.modes = _ARDUPILOT if self.ardupilot else _PX4
        #: Mode name → custom_mode of this personality.
        self.modes_by_name = (dict(ARDUCOPTER_MODES) if self.ardupilot
                              else {**PX4_MODES, "RTL": _PX4_RTL})
        self.mode = ARDUCOPTER_MODES["STABILIZE"] if self.ardupilot else PX4_MODES["HOLD"]
        self.armed = False
        self.t = 0.0
        self.events: deque[tuple[int, str]] = deque(maxlen=32)
        self.changed = False  # mode or arming changed: announce with a heartbeat now
        self.setpoints = SetpointTracker(vehicle, self.ardupilot)
        self._armed_at = 0.0
        self._landed_at = 0.0
        self._takeoff_height: float | None = None
        self._landing = False
        self.home = vehicle.position.copy()
        self.fence = FenceMonitor(params, self.ardupilot)
        params.add_listener(lambda name, value: self._apply_limits())
        self._apply_limits()

    # --- queries ------------------------------------------------------------------------
    @property
    def spec(self) -> ModeSpec:
        """The current mode's behaviour."""
        return self.modes[self.mode]

    def position_ok(self) -> bool:
        """Whether the simulated EKF has a position (after ``ekf_delay``)."""
        return self.t >= self.ekf_delay

    @property
    def landed(self) -> bool:
        """Whether the vehicle rests on the ground."""
        return self.vehicle.landed

    @property
    def taking_off(self) -> bool:
        """Whether a takeoff is climbing."""
        return self._takeoff_height is not None

    @property
    def landing(self) -> bool:
        """Whether a descent to touchdown (LAND, end of RTL) is under way."""
        return self._landing and not self.vehicle.landed

    def _say(self, text: str, severity: int = _WARNING) -> None:
        self.events.append((severity, text))

    # --- limits from parameters ----------------------------------------------------------
    def _apply_limits(self) -> None:
        p, lim = self.params, self.vehicle.limits
        if self.ardupilot:
            lim[2] = p.get("WPNAV_SPEED", 500.0) / 100.0
            lim[3] = p.get("WPNAV_SPEED_UP", 250.0) / 100.0
            lim[4] = p.get("WPNAV_SPEED_DN", 150.0) / 100.0
            lim[5] = lim[6] = p.get("WPNAV_ACCEL", 250.0) / 100.0
            if self.mode == ARDUCOPTER_MODES["BRAKE"]:
                lim[5] = lim[6] = _BRAKE_DECEL
        else:
            lim[2] = p.get("MPC_XY_VEL_MAX", 12.0)
            lim[3] = p.get("MPC_Z_VEL_MAX_UP", 3.0)
            lim[4] = p.get("MPC_Z_VEL_MAX_DN", 1.5)
            lim[5] = lim[6] = p.get("MPC_ACC_HOR", 3.0)
        lim[2:7] = np.maximum(lim[2:7], 0.05)

    def _land_speed(self) -> float:
        if self.ardupilot:
            return max(self.params.get("LAND_SPEED", 50.0), 5.0) / 100.0
        return max(self.params.get("MPC_LAND_SPEED", 0.7), 0.05)

    # --- commands --------------------------------------------------------------------------
    def set_mode(self, custom_mode: int) -> int:
        """Switch flight mode (DO_SET_MODE, SET_MODE); returns the MAV_RESULT."""
        custom_mode = int(custom_mode)
        spec = self.modes.get(custom_mode)
        if spec is None:
            known = custom_mode in ARDUCOPTER_MODES.values() if self.ardupilot else False
            why = "not simulated" if known else "unknown mode"
            self._say(f"Mode change to {custom_mode} failed: {why}")
            return UNSUPPORTED if known else FAILED
        if custom_mode == self.mode:
            return ACCEPTED
        if spec.needs_position and not self.position_ok():
            self._say("Mode change failed: requires position")
            return TEMPORARILY_REJECTED
        if spec.kind == "guided" and not self.ardupilot and not self.setpoints.streaming(self.t):
            self._say("Offboard: no setpoint stream (> 2 Hz for > 1 s)")
            return TEMPORARILY_REJECTED
        self._enter(custom_mode)
        return ACCEPTED

    def _enter(self, custom_mode: int) -> None:
        self.mode = custom_mode
        self.changed = True
        self._apply_limits()
        self._landing = False
        self._takeoff_height = None
        kind = self.spec.kind
        v = self.vehicle
        if kind == "guided" and not self.ardupilot and self.setpoints.apply_latest(self.t):
            return
        if not v.landed:
            self.setpoints.stop_here()
        if kind == "land":
            self._begin_descent()
        elif kind == "takeoff" and self.armed and v.landed:
            self._begin_takeoff(self.params.get("MIS_TAKEOFF_ALT", 2.5))
        elif kind == "rtl" and not v.landed:
            v.target[0:2] = self.home[0:2]

    def arm(self, arm: bool, force: bool = False) -> int:
        """Arm or disarm (COMPONENT_ARM_DISARM, ``force`` = param2 21196)."""
        v = self.vehicle
        if not arm:
            if not self.armed:
                return ACCEPTED
            if not v.landed and not force:
                self._say("Disarm: vehicle is flying")
                return DENIED
            if self.land_undetected and not force:
                return FAILED  # ArduCopter: not land_complete, so still "flying"
            self._disarm("Disarming motors")
            return ACCEPTED
        if self.armed:
            return ACCEPTED
        if self.deny_arm:
            self._say("PreArm: simulated pre-arm failure")
            return DENIED
        if not self.spec.allows_arming:
            self._say("Arm: Mode not armable")
            return DENIED
        if not force:
            limit = math.radians(self.params.get("ANGLE_MAX", 3000.0) / 100.0)
            if not v.landed or v.tilt() > min(limit, math.radians(30.0)):
                self._say("Arm: Leaning" if v.landed else "Arm: vehicle is flying")
                return DENIED
            if self.spec.needs_position and not self.position_ok():
                self._say("PreArm: Need Position Estimate")
                return TEMPORARILY_REJECTED
            fence = self.fence.prearm_failure(v.position, self.home)
            if fence is not None:
                self._say(("PreArm: " if self.ardupilot else "Arming denied: ") + fence)
                return DENIED
            if (self.spec.kind == "guided" and not self.ardupilot
                    and not self.setpoints.streaming(self.t)):
                self._say("Arming denied: offboard setpoints not streaming")
                return TEMPORARILY_REJECTED
        self.armed = True
        self.changed = True
        self._armed_at = self.t
        if self.spec.kind == "takeoff" and v.landed:
            self._begin_takeoff(self.params.get("MIS_TAKEOFF_ALT", 2.5))
        return ACCEPTED

    def takeoff(self, altitude: float) -> int:
        """NAV_TAKEOFF: ArduPilot param7 m above home; PX4 param7 m AMSL (NaN: default)."""
        v = self.vehicle
        if self.ardupilot:
            if self.spec.kind != "guided" or not self.armed or not v.landed:
                self._say("Takeoff: needs GUIDED, armed and landed")
                return FAILED
            if not (math.isfinite(altitude) and altitude > 0.0):
                return FAILED
            self._begin_takeoff(altitude)
            return ACCEPTED
        if not self.armed:
            self._say("Takeoff denied: disarmed")
            return TEMPORARILY_REJECTED
        if not self.position_ok():
            return TEMPORARILY_REJECTED
        default = self.params.get("MIS_TAKEOFF_ALT", 2.5)
        height = altitude - ORIGIN[2] - self.home[2] if math.isfinite(altitude) else default
        self._enter(PX4_MODES["TAKEOFF"] if v.landed else PX4_MODES["HOLD"])
        if v.landed:
            self._begin_takeoff(max(height, default))
        return ACCEPTED

    def setpoint(self, msg) -> bool:
        """A SET_POSITION_TARGET_LOCAL_NED; True when it now steers the vehicle."""
        applied = self.setpoints.receive(msg, self.t, self.spec.kind == "guided")
        if applied:
            self._takeoff_height = None
            if self.armed and self.vehicle.landed and self.setpoints.climbs():
                self.vehicle.lift_off()
        return applied

    # --- per tick ------------------------------------------------------------------------
    def update(self, t: float) -> None:
        """Timeouts, takeoff and landing progress, failsafes at sim time ``t`` (s)."""
        self.t = t
        v = self.vehicle
        kind = self.spec.kind
        if kind == "guided":
            if self.ardupilot:
                self.setpoints.check_timeout(t, guided_timeout(self.params))
            elif self.setpoints.age(t) > self.params.get("COM_OF_LOSS_T", 1.0):
                modes = offboard_loss_modes(self.params)
                name = "Return" if modes[0] == "RTL" else modes[0].title()
                self._say(f"Failsafe: offboard control lost, switching to {name}")
                self._failsafe(modes)
            elif self.armed and v.landed and self.setpoints.climbs():
                v.lift_off()
        response = self.fence.check(t, v.position, self.home, self.armed, v.landed)
        if response is not None:
            for severity, text in response.texts:
                self._say(text, severity)
            self._failsafe(response.modes)
        if self._takeoff_height is not None and abs(v.height() - self._takeoff_height) < _ARRIVED_M:
            self._takeoff_height = None
            if not self.ardupilot:
                self._enter(PX4_MODES["HOLD"])
        if kind == "rtl" and not self._landing and not v.landed:
            p = v.position
            if math.hypot(p[0] - self.home[0], p[1] - self.home[1]) < 0.2:
                self._begin_descent()
        if not v.landed:
            self._check_touchdown()
        elif self.armed and not self.land_undetected:
            delay = (self.params.get("DISARM_DELAY", 10.0) if self.ardupilot
                     else self.params.get("COM_DISARM_PRFLT", 10.0))
            if delay > 0.0 and t - max(self._armed_at, self._landed_at) > delay:
                self._disarm("Disarming: no takeoff" if self.ardupilot else "Auto-disarm")

    def _check_touchdown(self) -> None:
        v = self.vehicle
        if self._landing and v.ground_contact >= _TOUCHDOWN_S:
            v.settle()
            self._landed_at = self.t
            self._landing = False
            if self.land_detector_fails and self.armed and self.spec.kind == "land":
                self.land_undetected = True
                return
            self._say("Land complete", _INFO)
            if self.armed:
                self._disarm("Disarming motors")
        elif v.ground_contact >= _REST_S and (
                not self.armed or v.target[T_POS][2] <= v.ground_z + 0.05
                or v.target[T_VEL][2] < 0.0):
            v.settle()
            self._landed_at = self.t
            self._takeoff_height = None

    # --- manoeuvres ------------------------------------------------------------------------
    def _disarm(self, text: str) -> None:
        self.armed = False
        self.land_undetected = False
        self.changed = True
        self._takeoff_height = None
        self._say(text, _INFO)

    def _failsafe(self, modes: tuple[str, ...]) -> None:
        """Switch to the first of ``modes`` (names) that can run; DISARM/TERMINATE stop the
        motors."""
        for name in modes:
            if name in _STOPS_MOTORS:
                self._disarm("Flight termination" if name == "TERMINATE" else "Disarming")
                return
            custom = self.modes_by_name.get(name)
            if custom is None:
                continue
            if custom == self.mode:
                return
            if self.modes[custom].needs_position and not self.position_ok():
                continue
            self._enter(custom)
            return

    def _begin_takeoff(self, height: float) -> None:
        v = self.vehicle
        v.lift_off()
        p = v.position.copy()
        p[2] = v.ground_z + height
        hold_target(v.target, p, v.yaw())
        self._takeoff_height = height

    def _begin_descent(self) -> None:
        """Hold the horizontal position and sink at the land speed until touchdown."""
        v = self.vehicle
        self._landing = True
        if v.landed:
            return
        self.setpoints.stop_here()
        v.target[T_USE_Z] = 0.0
        v.target[T_VEL] = (0.0, 0.0, -self._land_speed())
        v.target[T_YAW] = v.shaper[6]
