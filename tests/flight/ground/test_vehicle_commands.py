"""Tests of commands with ACKs, retries and mode encoding, against a scripted UDP vehicle."""

from __future__ import annotations

import threading
import time

import pytest
from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES, PX4_MODES
from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.vehicle_commands import CommandRejected, VehicleCommands
from mavsysid.flight.loopback_ports import free_udp_port

from mavsysid.errors import JobFailedError
from tests.support.mavlink_peer import ScriptedVehicle

ACCEPTED, TEMPORARILY_REJECTED, DENIED = 0, 1, 2


def _connected(peer: ScriptedVehicle, port: int, speedup: float = 5.0):
    link = MavlinkLink(f"udp:127.0.0.1:{port}", clock=LinkClock(speedup))
    link.wait_heartbeat(10.0)
    said: list[str] = []
    return link, VehicleCommands(link, say=said.append), said


def test_refused_arm_names_the_result():
    """A DENIED arm raises at once with MAV_RESULT_DENIED (no retries)."""
    port = free_udp_port()
    with ScriptedVehicle(port, answer=lambda m: DENIED if m.command == 400 else ACCEPTED,
                         heartbeat_period=0.05) as peer:
        link, commands, _ = _connected(peer, port)
        with link, pytest.raises(CommandRejected, match="arm refused by the vehicle: "
                                 "MAV_RESULT_DENIED") as info:
            commands.arm()
        assert info.value.result_name == "MAV_RESULT_DENIED"
        assert len(peer.received_of("COMMAND_LONG")) == 1


def test_temporarily_rejected_mode_is_retried_then_confirmed():
    """GUIDED refused for now twice, then accepted: retried, and confirmed by the heartbeat."""
    port = free_udp_port()
    answers = iter([TEMPORARILY_REJECTED, TEMPORARILY_REJECTED, ACCEPTED])
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer:
        def answer(msg):
            result = next(answers)
            if result == ACCEPTED:
                peer.custom_mode = int(msg.param2)
            return result
        peer.answer = answer
        link, commands, said = _connected(peer, port)
        with link:
            commands.set_mode("GUIDED")
            assert link.vehicle.mode == "GUIDED"
        sent = peer.received_of("COMMAND_LONG")
        assert [(m.command, m.param1, m.param2) for m in sent] == [(176, 1.0, 4.0)] * 3
        assert sum("MAV_RESULT_TEMPORARILY_REJECTED, retrying" in s for s in said) == 2


def test_unanswered_command_is_resent_then_fails():
    """No ACK: sent `attempts` times with the confirmation counting up, then an error."""
    port = free_udp_port()
    with ScriptedVehicle(port, answer=lambda m: None, heartbeat_period=0.05) as peer:
        link, commands, _ = _connected(peer, port, speedup=10.0)
        with link, pytest.raises(JobFailedError, match=r"take-off to 2\.00 m: no COMMAND_ACK "
                                 r"from the vehicle after 3 attempts"):
            commands.takeoff(2.0)
        sent = peer.received_of("COMMAND_LONG")
        assert [m.confirmation for m in sent] == [0, 1, 2]
        assert sent[0].command == 22 and sent[0].param7 == 2.0


def test_px4_mode_is_main_and_sub_mode():
    """PX4 modes go out as param2 = main mode, param3 = sub mode."""
    port = free_udp_port()
    with ScriptedVehicle(port, autopilot=12, heartbeat_period=0.05) as peer:
        def answer(msg):
            peer.custom_mode = (int(msg.param2) << 16) | (int(msg.param3) << 24)
            return ACCEPTED
        peer.answer = answer
        link, commands, _ = _connected(peer, port)
        with link:
            commands.set_mode("HOLD")
            commands.set_mode("OFFBOARD")
            assert link.vehicle.custom_mode == PX4_MODES["OFFBOARD"]
        sent = peer.received_of("COMMAND_LONG")
        assert [(m.param1, m.param2, m.param3) for m in sent] == [(1, 4, 3), (1, 6, 0)]


def test_accepted_mode_never_shown_is_an_error():
    """An ACCEPTED mode change that no heartbeat confirms is reported with the actual mode."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer:
        peer.custom_mode = ARDUCOPTER_MODES["LOITER"]
        link, commands, _ = _connected(peer, port)
        with link, pytest.raises(JobFailedError, match="mode GUIDED was accepted but the "
                                 "vehicle still reports LOITER"):
            commands.set_mode("GUIDED")


def test_wait_position_follows_the_ekf_flags():
    """ArduPilot: position usable only once the EKF reports every position flag."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer:
        link, commands, said = _connected(peer, port, speedup=2.0)
        flags = [1 | 2 | 4 | 8 | 32]  # no POS_HORIZ_ABS yet
        stop = threading.Event()

        def telemetry():
            t0 = time.monotonic()
            while not stop.is_set():
                ms = int(2000 * (time.monotonic() - t0))
                peer.send(peer.conn.mav.local_position_ned_encode(ms, 0, 0, 0, 0, 0, 0))
                peer.send(peer.conn.mav.ekf_status_report_encode(flags[0], 0, 0, 0, 0, 0))
                time.sleep(0.02)

        thread = threading.Thread(target=telemetry, daemon=True)
        thread.start()
        try:
            with link:
                with pytest.raises(JobFailedError, match="no usable local position within "
                                   "1 s: EKF lacks POS_HORIZ_ABS"):
                    commands.wait_position(1.0)
                assert any("waiting for a usable local position" in s for s in said)
                flags[0] |= 16
                commands.wait_position(2.0)
                assert commands.position_problem() is None
        finally:
            stop.set()
            thread.join()
