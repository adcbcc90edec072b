"""Tests of the streamer's MAVLink link over real UDP sockets on 127.0.0.1."""

from __future__ import annotations

import hashlib
import socket
import time

import pytest
from mavsysid.flight.gc_freeze import frozen_collector
from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.ground.mavlink_link import HeartbeatLost, LinkClosed, MavlinkLink
from mavsysid.flight.loopback_ports import free_tcp_port, free_udp_port
from mavsysid.flight.mavlink_setup import load_mavutil

from mavsysid.errors import InputError, JobFailedError
from tests.support.mavlink_peer import ScriptedVehicle


def _read_tlog(path):
    """(timestamp, source system, type) of every record, read by pymavlink."""
    log = load_mavutil().mavlink_connection(str(path))
    out = []
    while (m := log.recv_match()) is not None:
        out.append((m._timestamp, m.get_srcSystem(), m.get_type()))
    log.close()
    return out


def test_tlog_holds_both_directions(tmp_path):
    """pymavlink reads back the vehicle's messages and ours, in order, stamped now."""
    port = free_udp_port()
    before = time.time()
    with ScriptedVehicle(port, heartbeat_period=0.1) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}", tmp_path / "flight.tlog") as link:
        link.wait_heartbeat(3.0)
        peer.send(peer.conn.mav.local_position_ned_encode(1000, 1.0, 2.0, -3.0, 0, 0, 0))
        link.send(link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        link.poll(0.3)
    records = _read_tlog(tmp_path / "flight.tlog")
    kinds = {(system, kind) for _, system, kind in records}
    assert {(1, "HEARTBEAT"), (1, "LOCAL_POSITION_NED"), (255, "COMMAND_LONG")} <= kinds
    stamps = [t for t, _, _ in records]
    assert stamps == sorted(stamps)
    assert before - 1.0 < stamps[0] and stamps[-1] < time.time() + 1.0
    arms = [m for m in peer.received_of("COMMAND_LONG") if m.command == 400]
    assert len(arms) == 1


def test_gcs_heartbeat_at_one_hertz_of_streamer_time(tmp_path):
    """The GCS HEARTBEAT (type GCS, autopilot INVALID) comes every streamer second."""
    port = free_udp_port()
    clock = LinkClock(speedup=10.0)
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}", clock=clock) as link:
        link.wait_heartbeat(10.0)
        # As the streamer does while it streams: late in the suite a full collection of
        # this process takes ~0.2 s, two streamer seconds at this speed-up.
        with frozen_collector(collect_first=True):
            link.start_heartbeat()
            start = time.monotonic()
            link.poll(15.0)  # 1.5 s of wall time
            elapsed = time.monotonic() - start
    beats = peer.received_of("HEARTBEAT")
    assert all(b.type == 6 and b.autopilot == 8 for b in beats)
    assert all((b.get_srcSystem(), b.get_srcComponent()) == (255, 190) for b in beats)
    assert abs(len(beats) - 10 * elapsed) <= 3


def test_vehicle_state_from_heartbeat(tmp_path):
    """The first autopilot heartbeat sets the target, the family, mode and armed state."""
    port = free_udp_port()
    with ScriptedVehicle(port, autopilot=12, heartbeat_period=0.05) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}") as link:
        peer.base_mode, peer.custom_mode = 1 | 128, 6 << 16
        v = link.wait_heartbeat(3.0)
        link.poll(0.2)
        assert (v.system, v.component) == (1, 1)
        assert v.autopilot is not None and v.autopilot.name == "PX4"
        assert v.mode == "OFFBOARD" and v.armed
        assert link.heartbeat_age() < 0.5


def test_heartbeat_loss_is_reported(tmp_path):
    """With the watch on, poll raises HeartbeatLost once the vehicle is silent too long."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}", heartbeat_loss=0.4) as link:
        link.wait_heartbeat(3.0)
        link.watch_heartbeat = True
        link.poll(0.3)
        peer.heartbeat_period = 0.0
        start = time.monotonic()
        with pytest.raises(HeartbeatLost, match="heartbeat lost"):
            link.poll(5.0)
        assert time.monotonic() - start < 1.0


def test_no_heartbeat_is_a_clear_error():
    """Nobody there: a one-line error naming the connection and the wait."""
    port = free_udp_port()
    with MavlinkLink(f"udp:127.0.0.1:{port}", clock=LinkClock(10.0)) as link, pytest.raises(
            JobFailedError, match=f"no vehicle heartbeat on udp:127.0.0.1:{port} within 2 s"):
        link.wait_heartbeat(2.0)


class _Every:
    """A ticker firing every ``period`` s, logging when."""

    def __init__(self, start: float, period: float) -> None:
        self.start, self.next, self.period, self.fired = start, start, period, []

    def next_deadline(self) -> float:
        return self.next

    def fire(self, now: float) -> None:
        self.fired.append(now)
        self.next += self.period


def test_ticker_fires_on_time_while_polling():
    """poll fires the ticker at its deadlines (spinning the last 2 ms), within a millisecond
    or two, never early."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.01), MavlinkLink(
            f"udp:127.0.0.1:{port}", spin=0.002) as link:
        link.wait_heartbeat(3.0)
        ticker = _Every(link.clock.now(), 0.02)
        link.set_ticker(ticker)
        link.poll(0.5)
        link.set_ticker(None)
    assert 24 <= len(ticker.fired) <= 26
    lateness = [t - (ticker.start + 0.02 * i) for i, t in enumerate(ticker.fired)]
    assert min(lateness) >= -1e-9 and sorted(lateness)[len(lateness) // 2] < 0.002


def test_signed_link_talks_to_a_signing_vehicle(tmp_path):
    """Same key: the vehicle is heard, and it receives our messages signed."""
    key = hashlib.sha256(b"secret").digest()
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05, signing_key=key) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}", signing_key=key) as link:
        link.wait_heartbeat(3.0)
        link.send(link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        link.poll(0.3)
    (arm,) = peer.received_of("COMMAND_LONG")
    assert arm.get_signed()
    assert link.rejected_signed == 0 and link.signing_problem() is None


def test_wrong_key_is_named():
    """Another key: no heartbeat gets through, and the error says the signature is wrong."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05,
                         signing_key=hashlib.sha256(b"theirs").digest()), MavlinkLink(
            f"udp:127.0.0.1:{port}", signing_key=hashlib.sha256(b"ours").digest(),
            clock=LinkClock(5.0)) as link, pytest.raises(JobFailedError,
                                                         match="wrong signature"):
        link.wait_heartbeat(2.0)


def test_unkeyed_link_notices_a_signing_vehicle():
    """Without a key the vehicle's signed messages are read, and the problem is named."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05,
                         signing_key=hashlib.sha256(b"theirs").digest()), MavlinkLink(
            f"udp:127.0.0.1:{port}") as link:
        link.wait_heartbeat(3.0)
        assert "--signing-key" in (link.signing_problem() or "")


@pytest.mark.parametrize("connect", ["udp:14550", "bogus:1.2.3.4:5", "tcp:127.0.0.1:x",
                                     "udpout:127.0.0.1:70000", "serial:"])
def test_bad_connection_strings(connect):
    """A malformed --connect is bad input, one line."""
    with pytest.raises(InputError, match="--connect"):
        MavlinkLink(connect)


def test_refused_tcp_connection_is_one_line():
    """Nothing listening on a TCP port: the job fails with the OS's reason."""
    port = free_udp_port()  # nothing listens on it over TCP either, most likely
    with pytest.raises(JobFailedError, match=f"cannot open tcp:127.0.0.1:{port}: "
                       "Connection refused"):
        MavlinkLink(f"tcp:127.0.0.1:{port}")


def test_closed_tcp_link_ends_in_one_line(capfd):
    """A vehicle closing the TCP link ends polling with LinkClosed; pymavlink prints nothing."""
    port = free_tcp_port()
    with socket.create_server(("127.0.0.1", port)) as server:
        server.settimeout(10.0)
        link = MavlinkLink(f"tcp:127.0.0.1:{port}")
        peer, _ = server.accept()
        peer.close()
        try:
            with pytest.raises(LinkClosed, match=f"tcp:127.0.0.1:{port} was closed"):
                for _ in range(200):  # the EOF shows on the first read after the close
                    link.poll(0.01)
        finally:
            link.close()
    assert "EOF" not in capfd.readouterr().out
