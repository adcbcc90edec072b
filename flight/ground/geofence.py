"""The flight box enforced by the autopilot: a geofence and a short guided timeout.

Before arming, `install_fence` gives the vehicle a fence around the operator's box plus
`FENCE_MARGIN` on every side, so that the box holds even when the streamer dies mid-flight
(kill -9, a crashed laptop), and shortens the time the autopilot keeps flying the last
velocity and acceleration it was sent:

- **ArduPilot** (Copter): an inclusion polygon (the box's corners) uploaded with the
  MAVLink mission protocol as mission type FENCE (MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
  items), FENCE_TYPE = max altitude + polygon (max altitude + circle around home when the
  polygon is refused), FENCE_ALT_MAX above home, FENCE_MARGIN, FENCE_ACTION = Brake or Land
  (stop where the breach is seen: in a box of a few metres, an RTL that climbs to RTL_ALT
  and flies back is the riskier move), FENCE_ENABLE = 1, GUID_TIMEOUT = `GUIDED_TIMEOUT`.
- **PX4**: the same polygon as a fence mission, GF_MAX_HOR_DIST / GF_MAX_VER_DIST around
  home (they stand alone if the mission is refused), GF_ACTION = Land, COM_OF_LOSS_T =
  `GUIDED_TIMEOUT` and COM_OBL_RC_ACT = Land (no ground station left to take over).

Local ENU corners become latitude/longitude through the vehicle's origin of its local frame
(GPS_GLOBAL_ORIGIN, else HOME_POSITION less its local offset). A vehicle that has no
working fence (parameters missing or refused, no origin) is refused in one line: flying a
calibration trajectory near the box edges without one is what sent a vehicle 44 m out of a
4 m box; ``--no-fence`` flies without it, on purpose. Every parameter goes
through the session's `ParameterSession`, which puts them back after the flight. The fence
points the vehicle held before are read first (`download_fence`) and kept in ``meta.json``
(``fence.points_before``); once the vehicle is disarmed they are put back
(`restore_fence_points`: uploaded again, or the fence mission cleared when there was none),
which returns ArduPilot's FENCE_TOTAL to its value before the flight.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.parameter_session import ParameterSession
from mavsysid.flight.ground.vehicle_commands import VehicleCommands

from mavsysid.errors import JobFailedError

__all__ = ["FENCE_MARGIN", "GUIDED_TIMEOUT", "SAFETY_PARAMETERS", "FencePlan", "VehicleOrigin",
           "download_fence", "fence_parameters", "fence_plan", "install_fence", "offset_lat_lon",
           "read_origin", "restore_fence_points", "upload_fence_items", "upload_fence_polygon"]

#: Distance from the box to the fence on every side and above, m: more than a tracking
#: error the streamer tolerates (1 m) so the fence never fires on a flight going well,
#: small enough that a breach still ends a few metres from the box.
FENCE_MARGIN = 1.5
#: Guided (ArduPilot GUID_TIMEOUT) / offboard (PX4 COM_OF_LOSS_T) timeout for the flight,
#: s: 25 setpoint periods at 50 Hz; at 2 m/s that is 1 m of flight on the last command.
GUIDED_TIMEOUT = 0.5
#: The parameters that keep a vehicle in its box (left in force while it still flies).
SAFETY_PARAMETERS = ("FENCE_ENABLE", "FENCE_TYPE", "FENCE_ALT_MAX", "FENCE_RADIUS",
                     "FENCE_MARGIN", "FENCE_ACTION", "GUID_TIMEOUT", "GF_ACTION",
                     "GF_MAX_HOR_DIST", "GF_MAX_VER_DIST", "COM_OF_LOSS_T", "COM_OBL_RC_ACT")
#: WGS-84 equatorial radius, m (ArduPilot's Location offsets use the same).
_EARTH_RADIUS = 6378137.0
_FENCE_MISSION = 1  # MAV_MISSION_TYPE_FENCE
_POLYGON_VERTEX_INCLUSION = 5001  # MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
_FRAME_GLOBAL = 0
_ALT_MAX, _CIRCLE, _POLYGON = 1, 2, 4  # FENCE_TYPE bits
_BRAKE_OR_LAND = 4  # ArduPilot FENCE_ACTION
_PX4_LAND = 5  # GF_ACTION Land mode
_PX4_OBL_LAND = 4  # COM_OBL_RC_ACT Land mode


@dataclass(frozen=True)
class VehicleOrigin:
    """Where the vehicle's local frame (LOCAL_POSITION_NED) starts: degrees, and which
    message said so."""

    lat: float
    lon: float
    source: str


@dataclass(frozen=True)
class FencePlan:
    """The fence for one flight.

    Attributes
    ----------
    box : tuple of 6 float
        The operator's box, m, local ENU [x_min, y_min, z_min, x_max, y_max, z_max].
    margin : float
        Fence distance outside the box, m.
    corners : tuple of (east, north)
        The fence polygon, m local ENU, counter-clockwise.
    polygon : tuple of (lat, lon)
        The same corners, degrees.
    alt_max : float
        Maximum altitude above home (the take-off point), m.
    radius : float
        Horizontal distance from home to the farthest fence corner, m (circle fallback,
        PX4 GF_MAX_HOR_DIST).
    """

    box: tuple[float, ...]
    margin: float
    corners: tuple[tuple[float, float], ...]
    polygon: tuple[tuple[float, float], ...]
    alt_max: float
    radius: float


def offset_lat_lon(origin: VehicleOrigin, east: float, north: float) -> tuple[float, float]:
    """Latitude and longitude (deg) of a point ``east``, ``north`` m from ``origin``
    (local tangent plane: exact to millimetres over a flight box)."""
    lat = origin.lat + math.degrees(north / _EARTH_RADIUS)
    lon = origin.lon + math.degrees(east / (_EARTH_RADIUS * math.cos(math.radians(origin.lat))))
    return lat, lon


def fence_plan(box: Sequence[float], margin: float, origin: VehicleOrigin,
               home: Sequence[float]) -> FencePlan:
    """The fence around ``box`` (m, local ENU) grown by ``margin`` (m), for a vehicle whose
    local frame starts at ``origin`` and which takes off from ``home`` (local ENU, m)."""
    x0, y0, _z0, x1, y1, z1 = (float(b) for b in box)
    corners = ((x0 - margin, y0 - margin), (x1 + margin, y0 - margin),
               (x1 + margin, y1 + margin), (x0 - margin, y1 + margin))
    polygon = tuple(offset_lat_lon(origin, e, n) for e, n in corners)
    radius = max(math.hypot(e - home[0], n - home[1]) for e, n in corners)
    return FencePlan(tuple(float(b) for b in box), margin, corners, polygon,
                     z1 + margin - float(home[2]), radius)


def read_origin(link: MavlinkLink, commands: VehicleCommands, timeout: float = 5.0
                ) -> VehicleOrigin | None:
    """The vehicle's local-frame origin: GPS_GLOBAL_ORIGIN, else HOME_POSITION shifted by
    its local x, y; None when neither comes within ``timeout`` streamer s."""
    got: dict[str, VehicleOrigin] = {}

    def listen(msg: Any, _t: float) -> None:
        kind = msg.get_type()
        if kind == "GPS_GLOBAL_ORIGIN" and (msg.latitude or msg.longitude):
            got[kind] = VehicleOrigin(msg.latitude * 1e-7, msg.longitude * 1e-7, kind)
        elif kind == "HOME_POSITION" and (msg.latitude or msg.longitude):
            home = VehicleOrigin(msg.latitude * 1e-7, msg.longitude * 1e-7, kind)
            lat, lon = offset_lat_lon(home, -msg.y, -msg.x)  # x north, y east (NED)
            got[kind] = VehicleOrigin(lat, lon, kind)

    link.add_listener(listen)
    try:
        for name in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
            commands.request_message(name)
        deadline = link.clock.now() + timeout
        while "GPS_GLOBAL_ORIGIN" not in got and link.clock.now() < deadline:
            link.poll(0.05)
            if "HOME_POSITION" in got:  # a moment more for the better answer
                deadline = min(deadline, link.clock.now() + 0.5)
    finally:
        link.remove_listener(listen)
    return got.get("GPS_GLOBAL_ORIGIN") or got.get("HOME_POSITION")


#: The fields of a stored fence point, as `download_fence` returns them (MISSION_ITEM_INT).
_ITEM_FIELDS = ("frame", "command", "param1", "param2", "param3", "param4", "x", "y", "z")


def download_fence(link: MavlinkLink, timeout: float = 10.0) -> list[dict[str, float]] | None:
    """The fence points the vehicle holds (mission type FENCE), or None if it did not say.

    Parameters
    ----------
    link : MavlinkLink
        The vehicle.
    timeout : float
        How long the whole download may take, streamer s.

    Returns
    -------
    list of dict or None
        One dict per point, the MISSION_ITEM_INT fields of `_ITEM_FIELDS` (x, y in degE7);
        an empty list for a vehicle without fence points.
    """
    v, mav = link.vehicle, link.mav
    got: dict[str, Any] = {"items": {}}

    def listen(msg: Any, _t: float) -> None:
        if getattr(msg, "mission_type", 0) != _FENCE_MISSION:
            return
        if msg.get_type() == "MISSION_COUNT":
            got["count"] = msg.count
        elif msg.get_type() == "MISSION_ITEM_INT":
            got["items"][msg.seq] = {name: getattr(msg, name) for name in _ITEM_FIELDS}

    link.add_listener(listen)
    try:
        clock = link.clock
        deadline, asked = clock.now() + timeout, -math.inf
        while clock.now() < deadline:
            count = got.get("count")
            if count is not None and len(got["items"]) >= count:
                link.send(mav.mission_ack_encode(v.system, v.component, 0,
                                                 mission_type=_FENCE_MISSION))
                return [got["items"][i] for i in range(count)]
            if clock.now() - asked > 1.0:  # ask (again) for what is missing
                asked = clock.now()
                if count is None:
                    link.send(mav.mission_request_list_encode(v.system, v.component,
                                                              mission_type=_FENCE_MISSION))
                else:
                    seq = min(set(range(count)) - set(got["items"]))
                    link.send(mav.mission_request_int_encode(v.system, v.component, seq,
                                                             mission_type=_FENCE_MISSION))
            link.poll(0.05)
        return None
    finally:
        link.remove_listener(listen)


def upload_fence_polygon(link: MavlinkLink, polygon: Sequence[tuple[float, float]],
                         timeout: float = 10.0) -> str | None:
    """Upload ``polygon`` (lat, lon deg) as one inclusion polygon, mission type FENCE.

    Returns
    -------
    str or None
        None when the vehicle acknowledged it (MAV_MISSION_ACCEPTED), else why not.
    """
    items = [{"frame": _FRAME_GLOBAL, "command": _POLYGON_VERTEX_INCLUSION,
              "param1": float(len(polygon)), "param2": 0.0, "param3": 0.0, "param4": 0.0,
              "x": round(lat * 1e7), "y": round(lon * 1e7), "z": 0.0} for lat, lon in polygon]
    return upload_fence_items(link, items, timeout)


def restore_fence_points(link: MavlinkLink, points: Sequence[dict[str, float]],
                         timeout: float = 10.0) -> str | None:
    """Put back the fence points ``points`` (`download_fence`): upload them, or clear the
    fence mission when there were none. None when acknowledged, else why not.

    Parameters
    ----------
    link : MavlinkLink
        The vehicle.
    points : sequence of dict
        What the vehicle held before the flight.
    timeout : float
        Streamer s for the whole exchange.
    """
    if points:
        return upload_fence_items(link, points, timeout)
    v, mav = link.vehicle, link.mav
    acks: list[Any] = []

    def listen(msg: Any, _t: float) -> None:
        if msg.get_type() == "MISSION_ACK" and getattr(msg, "mission_type", 0) == _FENCE_MISSION:
            acks.append(msg)

    link.add_listener(listen)
    try:
        deadline, sent = link.clock.now() + timeout, -math.inf
        while link.clock.now() < deadline:
            if acks:
                return None if acks[0].type == 0 else link.enum_name("MAV_MISSION_RESULT",
                                                                       acks[0].type)
            if link.clock.now() - sent > 1.5:
                sent = link.clock.now()
                link.send(mav.mission_clear_all_encode(v.system, v.component,
                                                       mission_type=_FENCE_MISSION))
            link.poll(0.05)
        return f"no MISSION_ACK to MISSION_CLEAR_ALL within {timeout:g} s"
    finally:
        link.remove_listener(listen)


def upload_fence_items(link: MavlinkLink, items: Sequence[dict[str, float]],
                       timeout: float = 10.0) -> str | None:
    """Upload fence points (the fields of `download_fence`), mission type FENCE.

    Parameters
    ----------
    link : MavlinkLink
        The vehicle.
    items : sequence of dict
        The points, in order.
    timeout : float
        Streamer s for the whole upload.

    Returns
    -------
    str or None
        None when the vehicle acknowledged it (MAV_MISSION_ACCEPTED), else why not.
    """
    v, mav = link.vehicle, link.mav
    events: list[Any] = []

    def listen(msg: Any, _t: float) -> None:
        if msg.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK") and (
                getattr(msg, "mission_type", 0) == _FENCE_MISSION):
            events.append(msg)

    link.add_listener(listen)
    try:
        clock = link.clock
        deadline = clock.now() + timeout
        count_sent = -math.inf
        requested = False
        while clock.now() < deadline:
            if not requested and clock.now() - count_sent > 1.5:  # lost: send again
                link.send(mav.mission_count_encode(v.system, v.component, len(items),
                                                   mission_type=_FENCE_MISSION))
                count_sent = clock.now()
            link.poll(0.05)
            while events:
                msg = events.pop(0)
                if msg.get_type() == "MISSION_ACK":
                    if msg.type == 0:
                        return None
                    return link.enum_name("MAV_MISSION_RESULT", msg.type)
                requested = True
                if 0 <= msg.seq < len(items):
                    link.send(_item_message(mav, v, items[msg.seq], msg.seq))
        return f"no MISSION_ACK within {timeout:g} s" if requested else (
            f"no answer to MISSION_COUNT within {timeout:g} s")
    finally:
        link.remove_listener(listen)


def _item_message(mav: Any, v: Any, item: dict[str, float], seq: int) -> Any:
    """The MISSION_ITEM_INT of one fence point, whichever request asked for it: the float
    MISSION_ITEM is deprecated, and ArduCopter answers it with "GCS should send
    MISSION_ITEM_INT"."""
    return mav.mission_item_int_encode(
        v.system, v.component, seq, int(item["frame"]), int(item["command"]), 0, 1,
        float(item["param1"]), float(item["param2"]), float(item["param3"]),
        float(item["param4"]), int(item["x"]), int(item["y"]), float(item["z"]),
        mission_type=_FENCE_MISSION)


def fence_parameters(autopilot: Autopilot, plan: FencePlan, polygon_ok: bool
                     ) -> tuple[dict[str, float], dict[str, float]]:
    """(required, optional) parameter values of the fence ``plan`` on ``autopilot``; the
    polygon is used when ``polygon_ok`` (uploaded and acknowledged)."""
    if autopilot is Autopilot.ARDUPILOT:
        kind = _ALT_MAX | (_POLYGON if polygon_ok else _CIRCLE)
        required = {"FENCE_TYPE": kind, "FENCE_ALT_MAX": round(plan.alt_max, 2),
                    "FENCE_ACTION": _BRAKE_OR_LAND}
        if not polygon_ok:
            required["FENCE_RADIUS"] = math.ceil(plan.radius)
        required["FENCE_ENABLE"] = 1  # last: the fence is complete when it switches on
        return required, {"FENCE_MARGIN": plan.margin, "GUID_TIMEOUT": GUIDED_TIMEOUT}
    required = {"GF_MAX_HOR_DIST": math.ceil(plan.radius), "GF_MAX_VER_DIST":
                math.ceil(plan.alt_max), "GF_ACTION": _PX4_LAND}
    return required, {"COM_OF_LOSS_T": GUIDED_TIMEOUT, "COM_OBL_RC_ACT": _PX4_OBL_LAND}


def install_fence(link: MavlinkLink, commands: VehicleCommands, params: ParameterSession,
                  box: Sequence[float], home: Sequence[float], margin: float = FENCE_MARGIN,
                  say: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Give the vehicle the fence of ``box`` + ``margin`` before arming (module docstring).

    Parameters
    ----------
    home : sequence of 3 float
        The vehicle's position on the ground, m local ENU (home once it arms).

    Returns
    -------
    dict
        What was set, for ``meta.json``: kind, margin, polygon, altitude, radius, origin.

    Raises
    ------
    JobFailedError
        "flight refused: …" in one line when the vehicle has no working fence.
    """
    say = say or (lambda _line: None)
    autopilot = link.vehicle.autopilot
    if autopilot is None:
        raise JobFailedError("flight refused: no geofence for an unknown autopilot")
    origin = read_origin(link, commands)
    if origin is None:
        raise _refused("it sent neither GPS_GLOBAL_ORIGIN nor HOME_POSITION")
    plan = fence_plan(box, margin, origin, home)
    # A dry run uploads nothing: the polygon counts as accepted.
    before = None if params.dry_run else download_fence(link)
    if before is None and not params.dry_run:
        say("warning: the vehicle did not list its fence points: the ones it holds are "
            "replaced and cannot be put back after the flight")
    problem = None if params.dry_run else upload_fence_polygon(link, plan.polygon)
    required, optional = fence_parameters(autopilot, plan, problem is None)
    if problem is not None:
        say(f"warning: the fence polygon was refused ({problem}); using "
            + ("a circle around home" if autopilot is Autopilot.ARDUPILOT
               else "GF_MAX_HOR_DIST around home"))
    present = params.read([*required, *optional], timeout=3.0)
    missing = [name for name in required if name not in present]
    if missing:
        raise _refused(f"it has no parameter {', '.join(missing)}")
    for name, value in {**optional, **required}.items():
        if name not in present:
            say(f"warning: the vehicle has no {name}; left as it is")
            continue
        try:
            params.set(name, value)
        except JobFailedError as error:
            if name in required:
                raise _refused(str(error)) from None
            say(f"warning: {error}")
    kind = "polygon" if problem is None else "circle"
    say(f"geofence{' (dry run: not installed)' if params.dry_run else ''}: {kind} "
        f"{margin:g} m outside the box, {plan.alt_max:.1f} m above home")
    return {"kind": kind, "margin_m": margin, "polygon_deg": [list(p) for p in plan.polygon],
            "corners_enu_m": [list(c) for c in plan.corners], "alt_max_m": plan.alt_max,
            "radius_m": plan.radius, "origin": {"lat": origin.lat, "lon": origin.lon,
                                                "source": origin.source},
            "points_before": before, "points_restored": problem is not None or params.dry_run}


def _refused(why: str) -> JobFailedError:
    return JobFailedError(f"flight refused: no working geofence on the vehicle ({why}); "
                          "--no-fence flies without one")
