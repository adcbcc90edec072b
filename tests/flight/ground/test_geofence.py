"""The geofence for the flight box: geometry, and installing it on the simulated vehicle."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.geofence import (
    GUIDED_TIMEOUT,
    VehicleOrigin,
    fence_plan,
    install_fence,
    offset_lat_lon,
    restore_fence_points,
    upload_fence_polygon,
)
from mavsysid.flight.ground.parameter_session import ParameterSession
from mavsysid.flight.ground.vehicle_commands import VehicleCommands

from mavsysid.errors import JobFailedError
from tests.support.sim_link import linked_sim

BOX = (-2.0, -1.0, 0.5, 3.0, 2.0, 2.5)
ORIGIN = VehicleOrigin(47.397, 8.545, "test")


def test_offset_matches_the_haversine_distance():
    rng = np.random.default_rng(7)
    for east, north in rng.uniform(-50.0, 50.0, size=(20, 2)):
        lat, lon = offset_lat_lon(ORIGIN, east, north)
        p1, p2 = math.radians(ORIGIN.lat), math.radians(lat)
        a = (math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2)
             * math.sin(math.radians(lon - ORIGIN.lon) / 2) ** 2)
        distance = 2 * 6378137.0 * math.asin(math.sqrt(a))
        assert distance == pytest.approx(math.hypot(east, north), rel=1e-4)
        assert (lat > ORIGIN.lat) == (north > 0) and (lon > ORIGIN.lon) == (east > 0)


def test_plan_is_the_box_grown_by_the_margin():
    plan = fence_plan(BOX, 1.5, ORIGIN, (0.5, 0.0, 0.1))
    xs, ys = zip(*plan.corners, strict=True)
    assert (min(xs), min(ys), max(xs), max(ys)) == (-3.5, -2.5, 4.5, 3.5)
    assert plan.alt_max == pytest.approx(2.5 + 1.5 - 0.1)  # above home, not the origin
    assert plan.radius == pytest.approx(math.hypot(4.0, 3.5))
    # Counter-clockwise: positive shoelace area equal to the grown box's.
    area = 0.5 * sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1)
                     in zip(plan.corners, plan.corners[1:] + plan.corners[:1], strict=True))
    assert area == pytest.approx(8.0 * 6.0)


@pytest.mark.parametrize("autopilot", [Autopilot.ARDUPILOT, Autopilot.PX4])
@pytest.mark.parametrize("stored", [0, 3])
def test_install_sets_the_fence_and_restore_puts_everything_back(autopilot, stored):
    """Parameters and fence points (none, or an operator's own triangle) come back as they
    were, ArduPilot's FENCE_TOTAL with them."""
    with linked_sim(autopilot, speedup=5.0) as (endpoint, link):
        own = [offset_lat_lon(ORIGIN, 10.0 * math.cos(a), 10.0 * math.sin(a))
               for a in np.linspace(0.0, 2 * math.pi, stored, endpoint=False)]
        if own:
            assert upload_fence_polygon(link, own) is None
        points_before = endpoint.autopilot.fence.items
        before = {p.name: p.value for p in endpoint.params}
        commands = VehicleCommands(link)
        commands.wait_position(30.0)
        params = ParameterSession(link)
        record = install_fence(link, commands, params, BOX, (0.0, 0.0, 0.0), 1.5)
        after = {p.name: p.value for p in endpoint.params}
        if autopilot is Autopilot.ARDUPILOT:
            assert record["kind"] == "polygon"
            assert after["FENCE_ENABLE"] == 1 and after["FENCE_TYPE"] == 1 | 4
            assert after["FENCE_ALT_MAX"] == pytest.approx(4.0)
            assert after["GUID_TIMEOUT"] == pytest.approx(GUIDED_TIMEOUT)
        else:
            assert after["GF_MAX_VER_DIST"] == 4.0 and after["GF_ACTION"] == 5
            assert after["COM_OF_LOSS_T"] == pytest.approx(GUIDED_TIMEOUT)
        changed = {n for n in after if after[n] != before[n]}
        counted = {"FENCE_TOTAL"} if autopilot is Autopilot.ARDUPILOT else set()
        assert changed == set(params.changed) | counted
        assert len(record["points_before"]) == stored
        assert params.restore() == []
        assert restore_fence_points(link, record["points_before"]) is None
        link.poll(0.5)
        assert {p.name: p.value for p in endpoint.params} == before
        assert endpoint.autopilot.fence.items == points_before


def test_a_vehicle_without_fence_parameters_is_refused_in_one_line(monkeypatch):
    with linked_sim() as (endpoint, link):
        commands = VehicleCommands(link)
        commands.wait_position(30.0)
        params = ParameterSession(link)
        # A firmware built without the fence: the parameter is unknown, never answered.
        monkeypatch.setattr(endpoint.params, "index", lambda name: None
                            if name == "FENCE_ALT_MAX" else type(endpoint.params).index(
                                endpoint.params, name))
        with pytest.raises(JobFailedError) as info:
            install_fence(link, commands, params, BOX, (0.0, 0.0, 0.0), 1.5)
        message = str(info.value)
        assert message.startswith("flight refused: no working geofence")
        assert "FENCE_ALT_MAX" in message and "--no-fence" in message and "\n" not in message
