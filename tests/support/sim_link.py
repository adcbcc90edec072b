"""The simulated vehicle in a background thread and a `MavlinkLink` to it on UDP loopback.

For tests of ground-side services (parameters, fences) that need a real MAVLink peer with
standard semantics but not a whole streamed flight: the link binds a free 127.0.0.1 port
first, the `SimEndpoint` that ``mavsysid sim`` runs sends to it.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.simvehicle.endpoint import SimEndpoint, SimSettings
from mavsysid.vehicle.config import load_vehicle

__all__ = ["linked_sim"]


@contextmanager
def linked_sim(autopilot: Autopilot = Autopilot.ARDUPILOT, speedup: float = 5.0,
               vehicle: str = "firefly", **settings: Any
               ) -> Iterator[tuple[SimEndpoint, MavlinkLink]]:
    """A running simulated vehicle and a connected `MavlinkLink` (heartbeat seen)."""
    port = free_udp_port()
    link = MavlinkLink(f"udpin:127.0.0.1:{port}", clock=LinkClock(speedup))
    endpoint = SimEndpoint(f"udpout:127.0.0.1:{port}", load_vehicle(vehicle),
                           SimSettings(autopilot=autopilot, speedup=speedup, **settings))
    thread = threading.Thread(target=endpoint.run, name="sim", daemon=True)
    thread.start()
    try:
        link.start_heartbeat()
        link.wait_heartbeat(15.0)
        yield endpoint, link
    finally:
        endpoint.stop()
        thread.join(10.0)
        link.close()
