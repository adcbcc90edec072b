"""The simulated autopilots' geofence: breach detection, breach actions, parameter semantics
(ArduCopter's FENCE_*, GUID_TIMEOUT; PX4's GF_*, COM_OF_LOSS_T/COM_OBL_RC_ACT), and the
fence upload over the mission protocol on a real loopback socket."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES, PX4_MODES, Autopilot
from mavsysid.flight.simvehicle.autopilot import SimAutopilot
from mavsysid.flight.simvehicle.fence import (
    ALT_MAX,
    CIRCLE,
    POLYGON,
    FenceItem,
    FenceMonitor,
    fence_names,
    fence_regions,
    guided_timeout,
    inside_polygon,
    offboard_loss_modes,
)
from mavsysid.flight.simvehicle.geodesy import enu_to_lat_lon, lat_lon_to_enu
from mavsysid.flight.simvehicle.link import mavlink as M
from mavsysid.flight.simvehicle.params import default_parameters
from mavsysid.flight.simvehicle.physics import ORIGIN, SimVehicle
from mavsysid.vehicle.config import load_vehicle

from tests.support.sim_gcs import running_sim

VERTEX = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
HOME = np.zeros(3)
#: A 3.5 m half-width square fence (a ±2 m box + 1.5 m margin), ENU corners.
SQUARE = ((-3.5, -3.5), (3.5, -3.5), (3.5, 3.5), (-3.5, 3.5))


def _polygon(corners=SQUARE, command=VERTEX) -> list[FenceItem]:
    items = []
    for east, north in corners:
        lat, lon = enu_to_lat_lon(east, north)
        items.append(FenceItem(command, M.MAV_FRAME_GLOBAL, (float(len(corners)), 0, 0, 0),
                               lat, lon))
    return items


def _monitor(autopilot: Autopilot, **values: float) -> FenceMonitor:
    params = default_parameters(autopilot, load_vehicle("quad_x"))
    for name, value in values.items():
        assert params.set(name, value)
    return FenceMonitor(params, autopilot is Autopilot.ARDUPILOT)


def test_lat_lon_conversion_is_the_local_tangent_plane():
    """1 m north is 1/111319.49 deg of latitude (WGS-84 equator radius); east is scaled by
    cos(latitude); the conversion round-trips."""
    lat, lon = enu_to_lat_lon(0.0, 1.0)
    assert (lat - ORIGIN[0]) * 111319.49 == pytest.approx(1.0, rel=1e-6)
    lat, lon = enu_to_lat_lon(1.0, 0.0)
    scale = 111319.49 * math.cos(math.radians(ORIGIN[0]))
    assert (lon - ORIGIN[1]) * scale == pytest.approx(1.0, rel=1e-6)
    rng = np.random.default_rng(3)
    for east, north in rng.uniform(-500.0, 500.0, (20, 2)):
        assert lat_lon_to_enu(*enu_to_lat_lon(east, north)) == pytest.approx((east, north),
                                                                             abs=1e-6)


def test_polygon_inclusion_and_fence_item_validation():
    """Even-odd inclusion for a concave polygon; an upload is checked as ArduPilot's
    loader does: vertex counts ≥ 3 and consistent, radius > 0, known commands only."""
    concave = np.array([(0, 0), (4, 0), (4, 4), (2, 1), (0, 4)], dtype=float)
    assert inside_polygon((1.0, 0.5), concave)
    assert not inside_polygon((2.0, 3.0), concave)  # in the notch
    assert not inside_polygon((5.0, 1.0), concave)
    result, regions = fence_regions(_polygon())
    assert result == M.MAV_MISSION_ACCEPTED and regions.count == 1
    assert regions.inclusion_polygons[0] == pytest.approx(np.array(SQUARE), abs=1e-6)
    assert fence_regions(_polygon(SQUARE[:2]))[0] == M.MAV_MISSION_INVALID_PARAM1
    short = _polygon()[:3]  # says 4 vertices, has 3
    assert fence_regions(short)[0] == M.MAV_MISSION_INVALID
    circle = FenceItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 0, (-1.0, 0, 0, 0), *ORIGIN[:2])
    assert fence_regions([circle])[0] == M.MAV_MISSION_INVALID_PARAM1
    waypoint = FenceItem(M.MAV_CMD_NAV_WAYPOINT, 0, (0, 0, 0, 0), *ORIGIN[:2])
    assert fence_regions([waypoint])[0] == M.MAV_MISSION_UNSUPPORTED


def test_inclusion_circle_and_exclusion_polygon():
    """Outside any inclusion zone or inside any exclusion zone is a polygon-fence breach."""
    lat, lon = enu_to_lat_lon(1.0, 0.0)
    circle = FenceItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 0, (5.0, 0, 0, 0), lat, lon)
    hole = _polygon(((-1, -1), (0, -1), (0, 0), (-1, 0)),
                    M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
    result, regions = fence_regions([circle, *hole])
    assert result == M.MAV_MISSION_ACCEPTED
    assert not regions.breached(5.9, 0.0)
    assert regions.breached(6.1, 0.0)
    assert regions.breached(-0.5, -0.5)


def test_ardupilot_fence_is_off_until_enabled_and_names_its_breaches():
    """FENCE_ENABLE 0 checks nothing; enabled, FENCE_TYPE picks altitude/circle/polygon
    (a polygon counts only once uploaded); breach texts are AC_Fence's wording."""
    fence = _monitor(Autopilot.ARDUPILOT)
    assert fence.upload(_polygon()) == M.MAV_MISSION_ACCEPTED
    far = np.array([310.0, 0.0, 150.0])
    assert fence.outside(far, HOME)[0] == 0
    assert fence.sys_status() == (True, False, True)  # present, not enabled, healthy
    fence.params.set("FENCE_ENABLE", 1)
    assert fence.outside(far, HOME) == (ALT_MAX | CIRCLE | POLYGON, pytest.approx(50.0))
    fence.params.set("FENCE_TYPE", ALT_MAX | POLYGON)
    fence.params.set("FENCE_ALT_MAX", 3.5)
    assert fence.outside(np.array([0.0, 0.0, 3.4]), HOME)[0] == 0
    assert fence.outside(np.array([0.0, 0.0, 3.5]), HOME)[0] == ALT_MAX  # at the limit
    assert fence.outside(np.array([3.6, 0.0, 2.0]), HOME)[0] == POLYGON
    assert fence_names(POLYGON) == "Polygon fence"
    assert fence_names(ALT_MAX | POLYGON) == "Max Alt and Polygon fences"
    assert fence_names(ALT_MAX | CIRCLE | POLYGON) == "Max Alt, Circle and Polygon fences"
    empty = _monitor(Autopilot.ARDUPILOT, FENCE_ENABLE=1, FENCE_TYPE=POLYGON)
    assert empty.prearm_failure(HOME, HOME) == "Fences enabled, but none selected"


@pytest.mark.parametrize(("action", "modes"), [
    (0, ()), (1, ("RTL", "LAND")), (2, ("LAND",)), (3, ("RTL", "LAND")),
    (4, ("BRAKE", "LAND")), (5, ("RTL", "LAND")), (9, ("RTL", "LAND"))])
def test_ardupilot_breach_action(action, modes):
    """FENCE_ACTION as ArduCopter's fence.cpp: 0 report only, 1 RTL or Land, 2 Land,
    3 SmartRTL (as RTL) or Land, 4 Brake or Land, 5 SmartRTL (as RTL) or Land, else 1."""
    fence = _monitor(Autopilot.ARDUPILOT, FENCE_ENABLE=1, FENCE_ACTION=action)
    fence.upload(_polygon())
    response = fence.check(1.0, np.array([4.0, 0.0, 2.0]), HOME, armed=True, landed=False)
    assert response.modes == modes
    assert response.texts == ((M.MAV_SEVERITY_NOTICE, "Polygon fence breached"),)
    assert fence.sys_status() == (True, action != 0, False)
    # Still outside: not a new breach; no check again before 40 ms (25 Hz).
    assert fence.check(1.5, np.array([4.5, 0.0, 2.0]), HOME, True, False) is None
    fence.check(2.0, np.array([0.0, 0.0, 2.0]), HOME, True, False)
    assert fence.sys_status()[2]  # back inside: healthy
    assert fence.check(2.02, np.array([4.0, 0.0, 2.0]), HOME, True, False) is None


def test_ardupilot_landed_disarms_far_lands_and_backup_fence_retriggers():
    """A breach seen landed disarms; more than 100 m outside forces LAND; 20 m beyond the
    first altitude/circle breach is a new breach (the backup fence)."""
    fence = _monitor(Autopilot.ARDUPILOT, FENCE_ENABLE=1, FENCE_TYPE=CIRCLE, FENCE_RADIUS=30,
                     FENCE_ACTION=4)
    landed = fence.check(0.0, np.array([31.0, 0.0, 0.0]), HOME, armed=True, landed=True)
    assert landed.modes == ("DISARM",) and landed.texts == ()
    fence = _monitor(Autopilot.ARDUPILOT, FENCE_ENABLE=1, FENCE_TYPE=CIRCLE, FENCE_RADIUS=30,
                     FENCE_ACTION=4)
    assert fence.check(0.0, np.array([131.0, 0.0, 5.0]), HOME, True, False).modes == ("LAND",)
    fence = _monitor(Autopilot.ARDUPILOT, FENCE_ENABLE=1, FENCE_TYPE=CIRCLE, FENCE_RADIUS=30,
                     FENCE_ACTION=4)
    assert fence.check(0.0, np.array([31.0, 0.0, 5.0]), HOME, True, False).modes == (
        "BRAKE", "LAND")
    assert fence.check(1.0, np.array([50.0, 0.0, 5.0]), HOME, True, False) is None
    assert fence.check(2.0, np.array([51.5, 0.0, 5.0]), HOME, True, False) is not None
    # Disarmed: breaches are tracked (pre-arm refuses) but nothing is done.
    fence = _monitor(Autopilot.ARDUPILOT, FENCE_ENABLE=1, FENCE_TYPE=CIRCLE, FENCE_RADIUS=30)
    assert fence.check(0.0, np.array([31.0, 0.0, 0.0]), HOME, armed=False, landed=True) is None
    assert fence.prearm_failure(np.array([31.0, 0.0, 0.0]), HOME) == "vehicle outside fence"


@pytest.mark.parametrize(("action", "modes"), [
    (0, None), (1, ()), (2, ("HOLD",)), (3, ("RTL",)), (4, ("TERMINATE",)), (5, ("LAND",))])
def test_px4_geofence_action(action, modes):
    """PX4: GF_MAX_HOR_DIST/GF_MAX_VER_DIST (0 = off) from home; GF_ACTION 0 none,
    1 warning, 2 Hold, 3 Return, 4 Terminate, 5 Land."""
    fence = _monitor(Autopilot.PX4, GF_ACTION=action)
    assert fence.outside(np.array([900.0, 0.0, 900.0]), HOME)[0] == 0  # both 0: off
    fence.params.set("GF_MAX_HOR_DIST", 5.0)
    fence.params.set("GF_MAX_VER_DIST", 3.0)
    assert fence.outside(np.array([5.0, 0.0, 3.0]), HOME)[0] == 0  # PX4: beyond, not at
    response = fence.check(0.0, np.array([4.0, 3.1, 1.0]), HOME, armed=True, landed=False)
    if modes is None:
        assert response.texts == () and response.modes == ()
    else:
        assert response.modes == modes
        assert response.texts == ((M.MAV_SEVERITY_CRITICAL,
                                   "Geofence violation: max horizontal distance exceeded"),)


def test_guided_and_offboard_timeout_parameters():
    """GUID_TIMEOUT acts as max(value, 0.1 s) (ModeGuided::get_timeout_ms); COM_OBL_RC_ACT
    picks PX4's offboard-loss mode, the RC modes (0–2) falling back to Hold without RC."""
    params = default_parameters(Autopilot.ARDUPILOT, load_vehicle("quad_x"))
    assert guided_timeout(params) == 3.0
    for value, expected in ((0.5, 0.5), (0.0, 0.1), (-1.0, 0.1), (5.0, 5.0)):
        params.set("GUID_TIMEOUT", value)
        assert guided_timeout(params) == pytest.approx(expected)
    px4 = default_parameters(Autopilot.PX4, load_vehicle("quad_x"))
    expected = {0: "HOLD", 1: "HOLD", 2: "HOLD", 3: "RTL", 4: "LAND", 5: "HOLD",
                6: "TERMINATE", 7: "DISARM"}
    for value, mode in expected.items():
        px4.set("COM_OBL_RC_ACT", value)
        assert offboard_loss_modes(px4) == (mode,)


def _flying_autopilot(autopilot: Autopilot, fence=(), **values: float) -> SimAutopilot:
    config = load_vehicle("quad_x")
    vehicle = SimVehicle(config, config.theta)
    params = default_parameters(autopilot, config)
    for name, value in values.items():
        params.set(name, value)
    ap = SimAutopilot(vehicle, autopilot, params, ekf_delay=0.0)
    ap.fence.upload(fence)
    ap.update(0.0)
    guided = ARDUCOPTER_MODES["GUIDED"] if autopilot is Autopilot.ARDUPILOT else None
    if guided is not None:
        assert ap.set_mode(guided) == M.MAV_RESULT_ACCEPTED
    assert ap.arm(True) == M.MAV_RESULT_ACCEPTED
    vehicle.lift_off()
    vehicle.y[0:3] = vehicle.shaper[0:3] = (0.0, 0.0, 2.0)
    return ap


def test_autopilot_brakes_on_a_polygon_breach_and_refuses_arming_outside():
    """ArduCopter with FENCE_ACTION 4: a breach switches GUIDED to BRAKE, which stops at
    BRAKE_MODE_DECEL_RATE (7.5 m/s²), and says so; outside the fence arming is refused."""
    ap = _flying_autopilot(Autopilot.ARDUPILOT, _polygon(), FENCE_ENABLE=1, FENCE_TYPE=POLYGON,
                           FENCE_ACTION=4)
    ap.vehicle.y[0] = 3.6
    ap.update(1.0)
    assert ap.mode == ARDUCOPTER_MODES["BRAKE"]
    assert (M.MAV_SEVERITY_NOTICE, "Polygon fence breached") in ap.events
    assert ap.vehicle.limits[5] == pytest.approx(7.5)
    config = load_vehicle("quad_x")
    outside = SimAutopilot(SimVehicle(config, config.theta, start=(4.0, 0.0, 0.0)),
                           Autopilot.ARDUPILOT, ap.params, ekf_delay=0.0)
    outside.fence.upload(_polygon())
    outside.update(0.0)
    assert outside.arm(True) == M.MAV_RESULT_DENIED
    assert outside.events[-1][1] == "PreArm: vehicle outside fence"


def test_px4_offboard_loss_follows_com_obl_rc_act():
    """PX4 in OFFBOARD: after COM_OF_LOSS_T without setpoints, COM_OBL_RC_ACT 4 lands."""
    ap = _flying_autopilot(Autopilot.PX4, COM_OF_LOSS_T=0.5, COM_OBL_RC_ACT=4)
    hold = SimpleNamespace(coordinate_frame=1, type_mask=0b110111111000, x=0.0, y=0.0, z=-2.0,
                           vx=0.0, vy=0.0, vz=0.0, afx=0.0, afy=0.0, afz=0.0, yaw=0.0,
                           yaw_rate=0.0)
    for t in np.arange(0.0, 1.21, 0.1):  # > 1 s of setpoints at 10 Hz: OFFBOARD may start
        ap.update(t)
        ap.setpoint(hold)
    assert ap.set_mode(PX4_MODES["OFFBOARD"]) == M.MAV_RESULT_ACCEPTED
    ap.update(1.6)
    assert ap.mode == PX4_MODES["OFFBOARD"]
    ap.update(1.75)
    assert ap.mode == PX4_MODES["LAND"]
    assert ap.events[-1][1] == "Failsafe: offboard control lost, switching to Land"


def _upload(gcs, items, mission_type=M.MAV_MISSION_TYPE_FENCE):
    """Upload ``items`` as a ground station does; the MISSION_ACK's result."""
    gcs.link.mav.mission_count_send(1, 1, len(items), mission_type)
    while True:
        msg = gcs.recv(["MISSION_REQUEST_INT", "MISSION_ACK"], timeout=3.0)
        assert msg is not None, "no answer in the upload"
        if msg.get_type() == "MISSION_ACK":
            return msg.type
        item = items[msg.seq]
        gcs.link.mav.mission_item_int_send(
            1, 1, msg.seq, item.frame, item.command, 0, 1, *item.params,
            round(item.lat * 1e7), round(item.lon * 1e7), 0.0, mission_type)


def test_fence_upload_download_and_health_over_loopback():
    """The mission protocol on a real socket: a polygon uploaded with pymavlink is
    accepted, downloaded back unchanged, used by the fence; a bad one is refused and leaves
    the fence as it was; SYS_STATUS shows the geofence present and enabled once switched on."""
    with running_sim(ekf_delay=0.0) as (endpoint, gcs):
        items = _polygon()
        assert _upload(gcs, items) == M.MAV_MISSION_ACCEPTED
        assert _upload(gcs, _polygon(SQUARE[:2])) == M.MAV_MISSION_INVALID_PARAM1
        assert _upload(gcs, items[:1], M.MAV_MISSION_TYPE_MISSION) == M.MAV_MISSION_UNSUPPORTED
        gcs.link.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_FENCE)
        count = gcs.recv("MISSION_COUNT", timeout=3.0)
        assert count.count == 4 and count.mission_type == M.MAV_MISSION_TYPE_FENCE
        for seq, item in enumerate(items):
            gcs.link.mav.mission_request_int_send(1, 1, seq, M.MAV_MISSION_TYPE_FENCE)
            back = gcs.recv("MISSION_ITEM_INT", timeout=3.0)
            assert (back.seq, back.command, back.param1) == (seq, VERTEX, 4.0)
            assert (back.x, back.y) == (round(item.lat * 1e7), round(item.lon * 1e7))
        assert endpoint.autopilot.fence.regions.count == 1
        gcs.link.mav.param_set_send(1, 1, b"FENCE_ENABLE", 1.0, M.MAV_PARAM_TYPE_INT8)
        assert gcs.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == "FENCE_ENABLE")
        status = gcs.recv("SYS_STATUS", timeout=gcs.wall(2.5))
        geofence = M.MAV_SYS_STATUS_GEOFENCE
        assert status.onboard_control_sensors_present & geofence
        assert status.onboard_control_sensors_enabled & geofence
        assert status.onboard_control_sensors_health & geofence
        fence_status = gcs.recv("FENCE_STATUS", timeout=gcs.wall(2.5))
        assert (fence_status.breach_status, fence_status.breach_count) == (0, 0)
        gcs.link.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_FENCE)
        assert gcs.recv("MISSION_ACK", 3.0).type == M.MAV_MISSION_ACCEPTED
        assert endpoint.autopilot.fence.regions.count == 0
