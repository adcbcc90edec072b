"""Link and start-up robustness: link loss by silence, pre-arm wait, arm retries, rotor
warning, the live meta.json writer. Against a scripted UDP vehicle (`ScriptedVehicle`)."""

from __future__ import annotations

import os
import threading
import time
from types import SimpleNamespace

import pytest
from mavsysid.flight.ground import meta_writer
from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.ground.link_state import (
    HeartbeatLost,
    VehicleState,
    link_loss_problem,
)
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.meta_writer import MetaWriter
from mavsysid.flight.ground.prearm import PrearmMonitor
from mavsysid.flight.ground.realtime import raise_priority, restore_scheduling
from mavsysid.flight.ground.rotor_watch import RotorWatch
from mavsysid.flight.ground.vehicle_commands import CommandRejected, VehicleCommands
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.formats.flight_dir import read_meta

from mavsysid.errors import JobFailedError
from tests.support.mavlink_peer import ScriptedVehicle

ACCEPTED, DENIED, FAILED = 0, 2, 4
PREARM = 1 << 28  # MAV_SYS_STATUS_PREARM_CHECK
GYRO = 1


class _Telemetry:
    """Sends ATTITUDE from the peer at ``rate`` Hz until stopped (a vehicle's telemetry)."""

    def __init__(self, peer: ScriptedVehicle, rate: float = 50.0) -> None:
        self.peer, self.period = peer, 1.0 / rate
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        t0 = time.monotonic()
        while not self.stop.wait(self.period):
            ms = int(1e3 * (time.monotonic() - t0))
            self.peer.send(self.peer.conn.mav.attitude_encode(ms, 0, 0, 0, 0, 0, 0))


class _CountingTicker:
    """A 50 Hz ticker recording when it fired (wall monotonic s)."""

    def __init__(self, clock: LinkClock, period: float = 0.02) -> None:
        self.clock, self.period = clock, period
        self.next = clock.now()
        self.fired: list[float] = []

    def next_deadline(self) -> float:
        return self.next

    def fire(self, now: float) -> None:
        self.fired.append(time.monotonic())
        self.next = now + self.period


def _sys_status(peer: ScriptedVehicle, healthy: int) -> None:
    present = PREARM | GYRO
    peer.send(peer.conn.mav.sys_status_encode(present, present, healthy, 0, 12000, -1, 90,
                                              0, 0, 0, 0, 0, 0))


def _text(peer: ScriptedVehicle, text: str) -> None:
    peer.send(peer.conn.mav.statustext_encode(3, text.encode()))


def test_link_loss_problem_thresholds():
    v = VehicleState(last_heartbeat=10.0, last_message=10.0)
    assert link_loss_problem(v, 10.9, 3.0, 1.0) is None
    assert "no message at all" in link_loss_problem(v, 11.1, 3.0, 1.0)
    assert link_loss_problem(v, 11.1, 3.0, None) is None  # silence not watched yet
    assert "nothing for 3.1 s" in link_loss_problem(v, 13.1, 3.0, None)


def test_silence_is_seen_within_the_limit_and_nothing_is_sent_after_it():
    """Telemetry at 50 Hz, heartbeats at 1 Hz: the vehicle stops; the loss is seen one
    link-loss limit after its last message (not after the 3 s heartbeat limit), and the
    ticker (the setpoint stream) never fires after the limit is passed."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=1.0) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}", heartbeat_loss=3.0, link_loss=0.5) as link:
        telemetry = _Telemetry(peer)
        link.wait_heartbeat(5.0)
        link.watch_heartbeat = link.watch_silence = True
        heard: list[float] = []
        link.add_listener(lambda _m, _t: heard.append(time.monotonic()))
        ticker = _CountingTicker(link.clock)
        link.set_ticker(ticker)
        link.poll(1.5)  # 1 Hz heartbeats and telemetry: no loss
        telemetry.stop.set()
        peer.heartbeat_period = 0.0
        with pytest.raises(HeartbeatLost, match="no message at all from the vehicle"):
            link.poll(5.0)
        seen = time.monotonic()
    assert seen - heard[-1] < 0.5 + 0.15
    assert ticker.fired[-1] <= heard[-1] + 0.5 + 0.005
    assert len([t for t in ticker.fired if t > heard[-1]]) <= 0.5 / 0.02 + 1


def test_heartbeats_alone_are_no_loss_before_the_telemetry_streams():
    """Without watch_silence (before telemetry is asked for) 1 Hz heartbeats suffice."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=1.0) as peer, MavlinkLink(
            f"udp:127.0.0.1:{port}", heartbeat_loss=3.0, link_loss=0.3) as link:
        link.wait_heartbeat(5.0)
        link.watch_heartbeat = True
        link.poll(1.6)  # a 1 s gap between heartbeats, longer than link_loss
        assert peer.heartbeat_period == 1.0


def test_silence_limit_has_a_wall_time_floor():
    port = free_udp_port()
    with MavlinkLink(f"udp:127.0.0.1:{port}", clock=LinkClock(8.0), link_loss=1.0) as link:
        assert link.link_loss == pytest.approx(2.0)  # 0.25 wall s x 8


def _connected(port: int) -> tuple[MavlinkLink, VehicleCommands, PrearmMonitor, list[str]]:
    link = MavlinkLink(f"udp:127.0.0.1:{port}", clock=LinkClock(1.0))
    link.wait_heartbeat(10.0)
    said: list[str] = []
    monitor = PrearmMonitor(link)
    link.add_listener(monitor.on_message)
    return link, VehicleCommands(link, say=said.append), monitor, said


def test_prearm_wait_until_healthy_then_returns():
    """PREARM_CHECK unhealthy for ~1 s with a PreArm text, then healthy: the wait says the
    text and returns once healthy."""
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.1) as peer:
        link, _, monitor, said = _connected(port)
        with link:
            start = time.monotonic()

            def vehicle() -> None:
                while time.monotonic() - start < 1.0:
                    _sys_status(peer, GYRO)
                    _text(peer, "PreArm: EKF not started")
                    time.sleep(0.1)
                _sys_status(peer, GYRO | PREARM)

            thread = threading.Thread(target=vehicle, daemon=True)
            thread.start()
            link.poll(0.3)
            monitor.wait_ready(10.0, said.append)
            thread.join()
        assert 0.9 < time.monotonic() - start < 3.0
        assert any("PreArm: EKF not started" in s and "PREARM_CHECK" in s for s in said)


def test_prearm_timeout_names_the_autopilot_reason():
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.1) as peer:
        link, _, monitor, said = _connected(port)
        with link:
            _sys_status(peer, GYRO)
            _text(peer, "PreArm: Gyros inconsistent")
            link.poll(0.3)
            with pytest.raises(JobFailedError, match=r"pre-arm checks still failing after "
                               r"0\.5 s \(unhealthy: PREARM_CHECK\); the autopilot says "
                               r"\"PreArm: Gyros inconsistent\""):
                monitor.wait_ready(0.5, said.append)


def test_failed_arm_is_retried_then_armed():
    """ArduPilot's FAILED (a pre-arm check not ready yet) twice, then ACCEPTED."""
    port = free_udp_port()
    answers = iter([FAILED, FAILED, ACCEPTED])
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer:
        def answer(_msg):
            result = next(answers)
            if result == ACCEPTED:
                peer.base_mode |= 128
            else:
                _text(peer, "PreArm: Need Position Estimate")
            return result
        peer.answer = answer
        link, commands, monitor, said = _connected(port)
        with link:
            commands.arm(retry_delay=0.2, explain=monitor.reason)
            assert link.vehicle.armed
        assert len(peer.received_of("COMMAND_LONG")) == 3
        assert sum("PreArm: Need Position Estimate" in s and "retrying" in s
                   for s in said) == 2


def test_arm_refused_every_time_reports_the_prearm_text():
    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer:
        def answer(_msg):
            _text(peer, "PreArm: Compass not calibrated")
            return FAILED
        peer.answer = answer
        link, commands, monitor, _ = _connected(port)
        with link, pytest.raises(CommandRejected, match=r"arm refused by the vehicle: "
                                 r"MAV_RESULT_FAILED \(PreArm: Compass not calibrated\)"):
            commands.arm(attempts=3, retry_delay=0.1, explain=monitor.reason)
        assert len(peer.received_of("COMMAND_LONG")) == 3


def _esc(rpm: tuple[int, ...]) -> SimpleNamespace:
    return SimpleNamespace(get_type=lambda: "ESC_TELEMETRY_1_TO_4", rpm=rpm)


def test_zero_rotor_speeds_while_armed_are_warned_once():
    vehicle, said = VehicleState(), []
    watch = RotorWatch(vehicle, said.append, after=3.0)
    for i in range(200):  # 4 s disarmed: no warning
        watch.on_message(_esc((0, 0, 0, 0)), 0.02 * i)
    assert not said
    vehicle.base_mode = 128
    for i in range(200, 400):  # 4 s armed at 0 rpm
        watch.on_message(_esc((0, 0, 0, 0)), 0.02 * i)
    assert len(said) == 1 and "0 rpm" in said[0]
    # What is true of SITL: its ESC rpm is never the rotor speed; no telemetry, outputs read.
    assert "never the rotor speed" in said[0] and "SIM_ESC_TELEM 0" in said[0]
    assert "set SIM_VIB_MOT_MAX" not in said[0]


def test_spinning_rotors_are_not_warned():
    vehicle, said = VehicleState(base_mode=128), []
    watch = RotorWatch(vehicle, said.append, after=3.0)
    for i in range(400):
        watch.on_message(_esc((0, 0, 0, 0) if i % 10 else (4000, 4000, 4000, 4000)), 0.02 * i)
    assert not said


def test_meta_writer_never_blocks_on_a_slow_disk(tmp_path, monkeypatch):
    """A write that takes 0.3 s (an fsync on a busy disk) does not delay `submit`; the
    newest snapshot wins and the final write is synchronous."""
    real = meta_writer.write_meta

    def slow(path, meta):
        time.sleep(0.3)
        real(path, meta)

    monkeypatch.setattr(meta_writer, "write_meta", slow)
    writer = MetaWriter(tmp_path / "meta.json")
    worst = 0.0
    for i in range(20):
        t0 = time.monotonic()
        writer.submit({"samples": i})
        worst = max(worst, time.monotonic() - t0)
        time.sleep(0.02)
    assert worst < 0.05
    time.sleep(0.7)
    assert read_meta(tmp_path / "meta.json")["samples"] == 19
    writer.close(final={"samples": 20, "running": False})
    assert read_meta(tmp_path / "meta.json") == {"samples": 20, "running": False}


def test_realtime_scheduling_is_taken_when_permitted_and_given_back():
    """raise_priority says what the thread runs with; restore_scheduling undoes it."""
    seen: dict[str, object] = {}

    def thread() -> None:  # a thread of its own: the policy is per thread
        seen["said"] = raise_priority()
        seen["during"] = os.sched_getscheduler(0)
        restore_scheduling()
        seen["after"] = os.sched_getscheduler(0)

    worker = threading.Thread(target=thread)
    worker.start()
    worker.join()
    said = str(seen["said"])
    assert said.startswith(("SCHED_RR", "normal ("))
    assert seen["during"] == (os.SCHED_RR if said.startswith("SCHED_RR") else os.SCHED_OTHER)
    assert seen["after"] == os.SCHED_OTHER


@pytest.mark.parametrize("failsafe", [True, False])
def test_a_mode_the_autopilot_changes_itself_is_quoted_not_called_a_pilot(failsafe):
    """GUIDED → LAND with ArduCopter's "EKF Failsafe" text just before: the stop names the
    autopilot's reason; without a text it may be a pilot."""
    from mavsysid.flight.ground.stream_control import FlightGuards, ModeTaken, SetpointStream
    from mavsysid.flight.ground.telemetry_recorder import SetpointHistory

    port = free_udp_port()
    with ScriptedVehicle(port, heartbeat_period=0.05) as peer:
        peer.custom_mode = 4  # GUIDED
        link, _, _, _ = _connected(port)
        with link:
            guards = FlightGuards(link, SetpointStream(link, SetpointHistory(), 50.0), None)
            link.add_listener(guards.on_message)
            link.poll(0.3)
            guards.expected_mode = 4
            if failsafe:
                _text(peer, "EKF Failsafe: changed to LAND Mode")
            peer.custom_mode = 9  # LAND
            with pytest.raises(ModeTaken) as taken:
                link.poll(2.0)
    text = str(taken.value)
    assert "from GUIDED to LAND" in text
    if failsafe:
        assert "the autopilot said: EKF Failsafe: changed to LAND Mode" in text
    else:
        assert "pilot takeover?" in text
