"""Geofences, breach actions and guided/offboard-loss timeouts of the simulated autopilots.

ArduCopter (``libraries/AC_Fence/AC_Fence.cpp``, ``ArduCopter/fence.cpp``): FENCE_ENABLE
switches fencing on; FENCE_TYPE is a bitmask of 1 max altitude above home
(FENCE_ALT_MAX), 2 circle of FENCE_RADIUS around home, 4 the inclusion/exclusion polygons
and circles uploaded with the mission protocol (mission_type FENCE). A breach is a new
breach when that fence was not breached before, or when the vehicle gets
20 m beyond the point of the first breach (the "backup fence" of the altitude and circle
fences). The check runs at 25 Hz (``fence_run_checks``, 40 ms). On a new breach, armed:
STATUSTEXT "<fences> breached" (NOTICE, not when landed); unless FENCE_ACTION is 0
(report only): landed → disarm; more than 100 m outside (AC_FENCE_GIVE_UP_DISTANCE,
altitude and circle only) → LAND; else by FENCE_ACTION: 1 RTL or Land, 2 Land,
3 SmartRTL or RTL or Land, 4 Brake or Land, 5 SmartRTL or Land, anything else as 1.
SmartRTL (retracing the path) is not simulated: RTL stands in for it. FENCE_MARGIN is
what ArduPilot's avoidance keeps from the fence in pilot modes; it does not move the
fence (only pre-arm checks compare it with the fence). SYS_STATUS: the geofence bit is
present when a fence is (``AC_Fence::present``), enabled when also FENCE_ENABLE and an
action, unhealthy while breached.

PX4 (``src/modules/navigator/geofence.cpp``, ``geofence_params.c``): GF_MAX_HOR_DIST and
GF_MAX_VER_DIST (0 = off) limit the distance from home; the geofence items (mission
type FENCE: inclusion/exclusion polygons and circles) must hold too. On a violation
GF_ACTION: 0 none, 1 warning, 2 Hold, 3 Return, 4 Terminate, 5 Land.

Guided timeouts: ArduCopter drops the velocity/acceleration feed-forward after
GUID_TIMEOUT (``ModeGuided::get_timeout_ms`` = max(GUID_TIMEOUT, 0.1 s); range
0.1–5 s). PX4 leaves OFFBOARD after COM_OF_LOSS_T (0–60 s) for COM_OBL_RC_ACT: 0 Position,
1 Altitude, 2 Manual, 3 Return, 4 Land, 5 Hold, 6 Terminate, 7 Disarm. The first three
are RC modes; with no RC (none here) PX4's failsafe falls back from them to Hold.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from mavsysid.flight.simvehicle.geodesy import lat_lon_to_enu
from mavsysid.flight.simvehicle.link import mavlink
from mavsysid.flight.simvehicle.params import ParameterTable

__all__ = [
    "ALT_MAX",
    "CIRCLE",
    "POLYGON",
    "FenceItem",
    "FenceMonitor",
    "FenceRegions",
    "FenceResponse",
    "fence_names",
    "fence_regions",
    "guided_timeout",
    "inside_polygon",
    "offboard_loss_modes",
]

M = mavlink
#: FENCE_TYPE bits (AC_FENCE_TYPE_*).
ALT_MAX, CIRCLE, POLYGON = 1, 2, 4
_NAMES = ((ALT_MAX, "Max Alt"), (CIRCLE, "Circle"), (POLYGON, "Polygon"))
_GIVE_UP_DISTANCE = 100.0      # m, AC_FENCE_GIVE_UP_DISTANCE
_BACKUP_DISTANCE = 20.0        # m, AC_FENCE_{ALT_MAX,CIRCLE_RADIUS}_BACKUP_DISTANCE (Copter)
_ARDUPILOT_PERIOD = 0.04       # s, Copter's fence check at 25 Hz
_PX4_PERIOD = 0.05             # s, the navigator loop (≥ 20 Hz)
_GUIDED_TIMEOUT_MIN = 0.1      # s, ModeGuided::get_timeout_ms
_POLY_INCLUSION = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
_POLY_EXCLUSION = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
_CIRCLE_INCLUSION = M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
_CIRCLE_EXCLUSION = M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
_RETURN_POINT = M.MAV_CMD_NAV_FENCE_RETURN_POINT
#: FENCE_ACTION → the modes ArduCopter tries, in order (fence.cpp's switch).
_ARDUPILOT_ACTIONS = {1: ("RTL", "LAND"), 2: ("LAND",), 3: ("RTL", "LAND"),
                      4: ("BRAKE", "LAND"), 5: ("RTL", "LAND")}
#: GF_ACTION → PX4's reaction ("TERMINATE": motors off).
_PX4_ACTIONS = {2: ("HOLD",), 3: ("RTL",), 4: ("TERMINATE",), 5: ("LAND",)}
#: COM_OBL_RC_ACT → PX4's reaction without RC.
_PX4_OFFBOARD_LOSS = {3: ("RTL",), 4: ("LAND",), 5: ("HOLD",), 6: ("TERMINATE",),
                      7: ("DISARM",)}


@dataclass(frozen=True)
class FenceItem:
    """One geofence mission item as uploaded (kept for download).

    Attributes
    ----------
    command : int
        MAV_CMD_NAV_FENCE_*.
    frame : int
    params : tuple of 4 float
        param1 (vertex count or radius, m) … param4.
    lat, lon : float
        Degrees.
    alt : float
    """

    command: int
    frame: int
    params: tuple[float, float, float, float]
    lat: float
    lon: float
    alt: float = 0.0


@dataclass(frozen=True)
class FenceRegions:
    """Uploaded fence zones in world ENU: polygons (n, 2) and circles (east, north, radius)."""

    inclusion_polygons: tuple[np.ndarray, ...] = ()
    exclusion_polygons: tuple[np.ndarray, ...] = ()
    inclusion_circles: tuple[tuple[float, float, float], ...] = ()
    exclusion_circles: tuple[tuple[float, float, float], ...] = ()

    @property
    def count(self) -> int:
        """Number of zones."""
        return (len(self.inclusion_polygons) + len(self.exclusion_polygons)
                + len(self.inclusion_circles) + len(self.exclusion_circles))

    def breached(self, east: float, north: float) -> bool:
        """Outside an inclusion zone or inside an exclusion zone (AC_PolyFence_loader)."""
        def in_circle(c: tuple[float, float, float]) -> bool:
            return math.hypot(east - c[0], north - c[1]) <= c[2]

        point = (east, north)
        return (any(not inside_polygon(point, p) for p in self.inclusion_polygons)
                or any(not in_circle(c) for c in self.inclusion_circles)
                or any(inside_polygon(point, p) for p in self.exclusion_polygons)
                or any(in_circle(c) for c in self.exclusion_circles))


@dataclass(frozen=True)
class FenceResponse:
    """What the autopilot does about a breach: STATUSTEXT lines and the modes it tries.

    ``modes`` are mode names tried in order until one is accepted; "DISARM" and
    "TERMINATE" stop the motors.
    """

    texts: tuple[tuple[int, str], ...] = ()
    modes: tuple[str, ...] = ()


def inside_polygon(point: Sequence[float], polygon: np.ndarray) -> bool:
    """Whether ``point`` (x, y) lies inside ``polygon`` ((n, 2) vertices), even-odd rule."""
    x, y = point
    inside = False
    n = len(polygon)
    for i in range(n):
        x1, y1 = polygon[i]
        x2, y2 = polygon[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def fence_regions(items: Sequence[FenceItem]) -> tuple[int, FenceRegions]:
    """The zones of a fence upload, and its MAV_MISSION_RESULT (ACCEPTED or why not).

    A polygon is ``param1`` consecutive vertex items of one kind, ``param1`` ≥ 3 and the
    same in each; a circle is one item with its radius (m, > 0) in ``param1``.
    """
    zones: dict[int, list] = {_POLY_INCLUSION: [], _POLY_EXCLUSION: [],
                              _CIRCLE_INCLUSION: [], _CIRCLE_EXCLUSION: []}
    i = 0
    while i < len(items):
        item = items[i]
        if item.command == _RETURN_POINT:
            i += 1
            continue
        if item.command not in zones:
            return M.MAV_MISSION_UNSUPPORTED, FenceRegions()
        if not (math.isfinite(item.lat) and math.isfinite(item.lon)):
            return M.MAV_MISSION_INVALID_PARAM5_X, FenceRegions()
        if item.command in (_CIRCLE_INCLUSION, _CIRCLE_EXCLUSION):
            radius = item.params[0]
            if not (math.isfinite(radius) and radius > 0.0):
                return M.MAV_MISSION_INVALID_PARAM1, FenceRegions()
            zones[item.command].append((*lat_lon_to_enu(item.lat, item.lon), float(radius)))
            i += 1
            continue
        count = item.params[0]
        if not (math.isfinite(count) and count >= 3 and count == int(count)):
            return M.MAV_MISSION_INVALID_PARAM1, FenceRegions()
        vertices = items[i:i + int(count)]
        if len(vertices) < count or any(v.command != item.command or v.params[0] != count
                                        for v in vertices):
            return M.MAV_MISSION_INVALID, FenceRegions()
        zones[item.command].append(np.array([lat_lon_to_enu(v.lat, v.lon) for v in vertices]))
        i += int(count)
    return M.MAV_MISSION_ACCEPTED, FenceRegions(
        tuple(zones[_POLY_INCLUSION]), tuple(zones[_POLY_EXCLUSION]),
        tuple(zones[_CIRCLE_INCLUSION]), tuple(zones[_CIRCLE_EXCLUSION]))


def fence_names(fences: int) -> str:
    """ArduPilot's wording of a FENCE_TYPE bitmask: "Max Alt and Polygon fences"."""
    names = [name for bit, name in _NAMES if fences & bit]
    text = names[-1] if len(names) < 2 else ", ".join(names[:-1]) + " and " + names[-1]
    return text + (" fences" if len(names) > 1 else " fence")


def guided_timeout(params: ParameterTable) -> float:
    """Seconds without a setpoint before ArduCopter's GUIDED drops the feed-forward."""
    return max(params.get("GUID_TIMEOUT", 3.0), _GUIDED_TIMEOUT_MIN)


def offboard_loss_modes(params: ParameterTable) -> tuple[str, ...]:
    """What PX4 switches to when OFFBOARD setpoints stop (COM_OBL_RC_ACT, no RC)."""
    return _PX4_OFFBOARD_LOSS.get(int(params.get("COM_OBL_RC_ACT", 0)), ("HOLD",))


class FenceMonitor:
    """The fence of one simulated autopilot: its zones, breach state and reactions.

    Parameters
    ----------
    params : ParameterTable
        Read live (FENCE_* on ArduPilot, GF_* on PX4).
    ardupilot : bool
        ArduCopter's semantics (else PX4's).
    """

    def __init__(self, params: ParameterTable, ardupilot: bool) -> None:
        self.params = params
        self.ardupilot = ardupilot
        self.items: tuple[FenceItem, ...] = ()
        self.regions = FenceRegions()
        #: Fences breached now (FENCE_TYPE bits), how often a new breach was seen.
        self.breaches = 0
        self.breach_count = 0
        #: Sim time of the latest breach, s (FENCE_STATUS breach_time).
        self.breach_time = 0.0
        self._next_check = 0.0
        self._alt_backup = 0.0
        self._circle_backup = 0.0

    def upload(self, items: Sequence[FenceItem]) -> int:
        """Replace the fence zones; the MAV_MISSION_RESULT (nothing changes unless ACCEPTED)."""
        result, regions = fence_regions(items)
        if result == M.MAV_MISSION_ACCEPTED:
            self.items, self.regions = tuple(items), regions
        return result

    # --- configuration ----------------------------------------------------------------
    def configured(self) -> int:
        """Fence kinds configured, enabled or not (FENCE_TYPE bits)."""
        p = self.params
        if self.ardupilot:
            kinds = int(p.get("FENCE_TYPE", 7)) & (ALT_MAX | CIRCLE | POLYGON)
            return kinds if self.regions.count else kinds & ~POLYGON
        return ((ALT_MAX if p.get("GF_MAX_VER_DIST", 0.0) > 0.0 else 0)
                | (CIRCLE if p.get("GF_MAX_HOR_DIST", 0.0) > 0.0 else 0)
                | (POLYGON if self.regions.count else 0))

    def enabled(self) -> int:
        """Fence kinds being checked (ArduPilot: only with FENCE_ENABLE)."""
        if self.ardupilot and not self.params.get("FENCE_ENABLE", 0):
            return 0
        return self.configured()

    def _action(self) -> int:
        return int(self.params.get("FENCE_ACTION" if self.ardupilot else "GF_ACTION",
                                   1 if self.ardupilot else 2))

    def sys_status(self) -> tuple[bool, bool, bool]:
        """SYS_STATUS geofence bit: (present, enabled, healthy)."""
        present = self.configured() != 0
        enabled = present and self.enabled() != 0 and self._action() != 0
        return present, enabled, not (present and self.breaches)

    # --- checking -----------------------------------------------------------------------
    def _limits(self) -> tuple[float, float]:
        p = self.params
        if self.ardupilot:
            return p.get("FENCE_ALT_MAX", 100.0), p.get("FENCE_RADIUS", 300.0)
        return p.get("GF_MAX_VER_DIST", 0.0), p.get("GF_MAX_HOR_DIST", 0.0)

    def outside(self, position: np.ndarray, home: np.ndarray) -> tuple[int, float]:
        """Enabled fences ``position`` (world ENU, m) is outside of, and by how far (m;
        altitude and circle only, as AC_Fence's breach distance)."""
        kinds = self.enabled()
        alt_max, radius = self._limits()
        height = float(position[2] - home[2])
        distance = math.hypot(position[0] - home[0], position[1] - home[1])
        out, beyond = 0, 0.0
        # ArduPilot breaches at the limit (>=), PX4 beyond it (>).
        over = (lambda a, b: a >= b) if self.ardupilot else (lambda a, b: a > b)
        if kinds & ALT_MAX and over(height, alt_max):
            out, beyond = out | ALT_MAX, max(beyond, height - alt_max)
        if kinds & CIRCLE and over(distance, radius):
            out, beyond = out | CIRCLE, max(beyond, distance - radius)
        if kinds & POLYGON and self.regions.breached(float(position[0]), float(position[1])):
            out |= POLYGON
        return out, beyond

    def check(self, t: float, position: np.ndarray, home: np.ndarray, armed: bool,
              landed: bool) -> FenceResponse | None:
        """Check at sim time ``t`` (at the autopilot's fence rate); the reaction to a new
        breach, else None."""
        if t < self._next_check:
            return None
        self._next_check = t + (_ARDUPILOT_PERIOD if self.ardupilot else _PX4_PERIOD)
        out, beyond = self.outside(position, home)
        new = self._new_breaches(out, position, home)
        if out and not self.breaches:
            self.breach_time = t
        self.breaches = out
        self.breach_count += bool(new)
        if not new or not armed:
            return None
        return self._ardupilot_response(new, beyond, landed) if self.ardupilot else (
            self._px4_response(new))

    def _new_breaches(self, out: int, position: np.ndarray, home: np.ndarray) -> int:
        """Breaches that are new, or beyond the 20 m backup fence (ArduPilot)."""
        new = out & ~self.breaches
        if not self.ardupilot:
            return new
        height = float(position[2] - home[2])
        distance = math.hypot(position[0] - home[0], position[1] - home[1])
        if out & ALT_MAX and (new & ALT_MAX or height >= self._alt_backup):
            new |= ALT_MAX
            self._alt_backup = height + _BACKUP_DISTANCE
        if out & CIRCLE and (new & CIRCLE or distance >= self._circle_backup):
            new |= CIRCLE
            self._circle_backup = distance + _BACKUP_DISTANCE
        return new

    def _ardupilot_response(self, new: int, beyond: float, landed: bool) -> FenceResponse:
        texts = () if landed else ((M.MAV_SEVERITY_NOTICE, f"{fence_names(new)} breached"),)
        action = self._action()
        if action == 0:
            return FenceResponse(texts)
        if landed:
            return FenceResponse(texts, ("DISARM",))
        if beyond > _GIVE_UP_DISTANCE:
            return FenceResponse(texts, ("LAND",))
        return FenceResponse(texts, _ARDUPILOT_ACTIONS.get(action, ("RTL", "LAND")))

    def _px4_response(self, new: int) -> FenceResponse:
        what = ("max vertical distance" if new & ALT_MAX else
                "max horizontal distance" if new & CIRCLE else "geofence")
        text = (M.MAV_SEVERITY_CRITICAL, f"Geofence violation: {what} exceeded")
        action = self._action()
        if action == 0:
            return FenceResponse()
        return FenceResponse((text,), _PX4_ACTIONS.get(action, ()))

    def prearm_failure(self, position: np.ndarray, home: np.ndarray) -> str | None:
        """Why the fence refuses arming (AC_Fence::pre_arm_check, PX4's geofence check)."""
        p = self.params
        if self.ardupilot and p.get("FENCE_ENABLE", 0):
            if not self.configured():
                return "Fences enabled, but none selected"
            kinds = self.configured()
            if kinds & CIRCLE and p.get("FENCE_RADIUS", 300.0) < p.get("FENCE_MARGIN", 2.0):
                return "FENCE_MARGIN is less than FENCE_RADIUS"
        if self.outside(position, home)[0]:
            return "vehicle outside fence" if self.ardupilot else "Vehicle outside geofence"
        return None
