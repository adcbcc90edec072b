"""A minimal pymavlink ground station for tests of the simulated vehicle (`mavsysid sim`).

`running_sim` starts a `SimEndpoint` in a background thread on 127.0.0.1 (UDP: the
ground station binds a free port first and the sim sends to it; TCP: the sim listens on
a free port and the ground station connects) and yields a `Gcs` talking to it. The
`Gcs` measures time in the vehicle's sim time (time_boot_ms), so tests do not depend on
the speedup except through wall-clock timeouts.

By default the sim runs in lock-step (``SimSettings.lockstep``) and the `Gcs` acknowledges
its frames whenever it is about to wait for the next message, so the vehicle never runs
ahead of what the test has read; it holds at its first frame (10 ms) until the first
acknowledgement, and what the `Gcs` sends takes effect at the tick after its next
acknowledgement (``lockstep=False``: the wall clock).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from mavsysid.flight.loopback_ports import free_tcp_port
from mavsysid.flight.simvehicle.clock import is_lockstep_stamp
from mavsysid.flight.simvehicle.endpoint import SimEndpoint, SimSettings
from mavsysid.flight.simvehicle.link import mavlink, mavutil
from mavsysid.vehicle.config import load_vehicle

__all__ = ["Gcs", "running_sim"]

M = mavlink



class Gcs:
    """A ground station (system 255, component 190) on a pymavlink link.

    Parameters
    ----------
    link : pymavlink mavfile
    speedup : float
        The sim's speedup, to turn sim-time waits into wall-clock timeouts.
    """

    def __init__(self, link, speedup: float) -> None:
        self.link = link
        self.speedup = speedup
        self.sim_time = 0.0
        self.seen: list[Any] = []
        self._ack_ms: int | None = None

    def wall(self, sim_seconds: float) -> float:
        """A wall-clock timeout for ``sim_seconds`` of sim time, with slack."""
        return sim_seconds / self.speedup + 3.0

    def recv(self, kinds: str | list[str] | None = None, timeout: float = 3.0,
             condition: Callable[[Any], bool] | None = None):
        """The next message of ``kinds`` meeting ``condition`` within ``timeout`` wall s."""
        kinds = [kinds] if isinstance(kinds, str) else kinds
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return None
            msg = self.link.recv_match(blocking=False)
            if msg is None:
                if self._ack_ms is not None:  # lock-step: all read, about to wait
                    self.link.mav.system_time_send(self._ack_ms * 1000, self._ack_ms)
                    self._ack_ms = None
                msg = self.link.recv_match(blocking=True, timeout=min(left, 0.2))
            if msg is None or msg.get_type() == "BAD_DATA":
                continue
            if is_lockstep_stamp(msg):
                self._ack_ms = msg.time_boot_ms
                self.sim_time = max(self.sim_time, msg.time_boot_ms / 1000.0)
                continue
            self.seen.append(msg)
            if hasattr(msg, "time_boot_ms") and msg.get_srcSystem() == 1:
                self.sim_time = max(self.sim_time, msg.time_boot_ms / 1000.0)
            # Untimed messages (ESC telemetry) get the time of the last timed one.
            msg.sim_time = self.sim_time
            if (kinds is None or msg.get_type() in kinds) and (condition is None
                                                               or condition(msg)):
                return msg

    def command(self, command: int, *params: float, timeout: float = 3.0) -> int | None:
        """Send COMMAND_LONG; its ACK's result (None: no ACK within ``timeout``)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.link.mav.command_long_send(1, 1, command, 0, *p)
        ack = self.recv("COMMAND_ACK", timeout, lambda m: m.command == command)
        return None if ack is None else ack.result

    def set_rate(self, msg_id: int, rate_hz: float) -> int | None:
        """SET_MESSAGE_INTERVAL in Hz (0: default, < 0: off)."""
        interval = 0.0 if rate_hz == 0 else (-1.0 if rate_hz < 0 else 1e6 / rate_hz)
        return self.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval)

    def wait_until(self, sim_t: float, kinds: str | list[str] = "ATTITUDE") -> None:
        """Read messages until the vehicle's time_boot_ms reaches ``sim_t`` s."""
        end = time.monotonic() + self.wall(max(sim_t - self.sim_time, 0.0))
        while self.sim_time < sim_t and time.monotonic() < end:
            self.recv(kinds, timeout=0.5)
        assert self.sim_time >= sim_t, f"sim time stuck at {self.sim_time} s"

    def collect(self, kinds: str | list[str], sim_seconds: float) -> list[Any]:
        """Every message of ``kinds`` over the next ``sim_seconds`` of sim time."""
        out: list[Any] = []
        stop = self.sim_time + sim_seconds
        end = time.monotonic() + self.wall(sim_seconds)
        kinds = [kinds] if isinstance(kinds, str) else kinds
        while self.sim_time < stop and time.monotonic() < end:
            msg = self.recv(None, timeout=0.5)
            if msg is not None and msg.get_type() in kinds:
                out.append(msg)
        return out

    def setpoint(self, x=0.0, y=0.0, z=0.0, vx=0.0, vy=0.0, vz=0.0, ax=0.0, ay=0.0, az=0.0,
                 yaw=0.0, yaw_rate=0.0, type_mask: int = 0, frame: int = 1) -> None:
        """SET_POSITION_TARGET_LOCAL_NED (NED values)."""
        self.link.mav.set_position_target_local_ned_send(
            int(self.sim_time * 1000), 1, 1, frame, type_mask, x, y, z, vx, vy, vz, ax, ay, az,
            yaw, yaw_rate)

    def position(self, timeout: float = 3.0):
        """The next LOCAL_POSITION_NED."""
        return self.recv("LOCAL_POSITION_NED", timeout)


@contextmanager
def running_sim(vehicle: str = "firefly", transport: str = "udp",
                **settings: Any) -> Iterator[tuple[SimEndpoint, Gcs]]:
    """A simulated vehicle in a background thread and a ground station connected to it."""
    settings.setdefault("speedup", 5.0)
    settings.setdefault("lockstep", True)
    sim_settings = SimSettings(**settings)
    config = load_vehicle(vehicle)
    if transport == "udp":
        link = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255,
                                          source_component=190)
        endpoint = SimEndpoint(f"udpout:127.0.0.1:{link.port.getsockname()[1]}", config,
                               sim_settings)
    else:
        port = free_tcp_port()
        endpoint = SimEndpoint(f"tcpin:127.0.0.1:{port}", config, sim_settings)
        link = None
    thread = threading.Thread(target=endpoint.run, name="sim", daemon=True)
    thread.start()
    try:
        if link is None:
            link = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                              source_component=190)
        gcs = Gcs(link, sim_settings.speedup)
        if gcs.recv("HEARTBEAT", timeout=15.0) is None:
            raise AssertionError("the simulated vehicle sent no HEARTBEAT")
        yield endpoint, gcs
    finally:
        endpoint.stop()
        thread.join(10.0)
        if link is not None:
            link.close()
