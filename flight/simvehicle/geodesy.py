"""Latitude and longitude of the simulated vehicle's world: the one flat-earth conversion.

The world ENU origin (0, 0, 0) sits at `mavsysid.flight.simvehicle.physics.ORIGIN`; over
the few hundred metres a flight spans, a local tangent plane (equirectangular, longitude
scaled by cos latitude at the origin) is exact to well under a millimetre per metre. The
telemetry (GLOBAL_POSITION_INT, HOME_POSITION) and the fence (polygons and circles arrive
as latitude/longitude) both convert here.
"""

from __future__ import annotations

import math

from mavsysid.flight.simvehicle.physics import ORIGIN

__all__ = ["EARTH_RADIUS", "enu_to_lat_lon", "lat_lon_to_enu"]

#: WGS-84 equatorial radius, m.
EARTH_RADIUS = 6378137.0
_LON_SCALE = math.cos(math.radians(ORIGIN[0]))


def enu_to_lat_lon(east: float, north: float) -> tuple[float, float]:
    """Latitude and longitude (deg) of the world point ``east``, ``north`` (m)."""
    lat = ORIGIN[0] + math.degrees(north / EARTH_RADIUS)
    lon = ORIGIN[1] + math.degrees(east / (EARTH_RADIUS * _LON_SCALE))
    return lat, lon


def lat_lon_to_enu(lat: float, lon: float) -> tuple[float, float]:
    """World east and north (m) of latitude ``lat`` and longitude ``lon`` (deg)."""
    north = math.radians(lat - ORIGIN[0]) * EARTH_RADIUS
    east = math.radians(lon - ORIGIN[1]) * EARTH_RADIUS * _LON_SCALE
    return east, north
