"""Lock-step: the vehicle's `SimClock` and the streamer's `LinkClock` without sockets, and
the same streamed flight on an idle and on an overloaded machine."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.ground import link_clock
from mavsysid.flight.ground.link_clock import LinkClock
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.simvehicle import clock as sim_clock
from mavsysid.flight.simvehicle.clock import LOCKSTEP_FRAME_US, SimClock, is_lockstep_stamp
from mavsysid.flight.simvehicle.link import mavlink as M
from mavsysid.formats.poselog import read_pose_log

from tests.support.stream_flights import SimProcess, export_excitation, flight_dir, run_stream

#: Busy processes competing for the cores in the loaded flight: with the flight's own
#: two, twice the 2 cores.
BUSY = 2


def _frame(ms: int, unix_us: int | None = None):
    return M.MAVLink_system_time_message(ms * 1000 if unix_us is None else unix_us, ms)


def test_stamps_are_told_from_ordinary_system_time():
    assert is_lockstep_stamp(_frame(10))
    assert not is_lockstep_stamp(_frame(10, unix_us=1_700_000_000_000_000))
    assert not is_lockstep_stamp(_frame(10, unix_us=0))
    assert not is_lockstep_stamp(_frame(0))


def test_vehicle_holds_from_its_first_frame_until_acknowledged_then_each_frame():
    clock = SimClock(0.002, speedup=100.0, lockstep=True)
    clock.start()
    clock.frame_sent(LOCKSTEP_FRAME_US)
    assert clock.held and not clock.due()  # nobody there yet: waits as long as it takes
    clock.acknowledge(LOCKSTEP_FRAME_US)
    assert not clock.held
    clock.frame_sent(2 * LOCKSTEP_FRAME_US)
    assert clock.held and not clock.due()
    clock.acknowledge(LOCKSTEP_FRAME_US)  # a repeated, old acknowledgement changes nothing
    assert clock.held
    clock.acknowledge(2 * LOCKSTEP_FRAME_US)
    assert not clock.held
    assert clock.stats().lockstep_frames == 2


def test_held_start_gives_up_on_a_peer_that_never_acknowledges(monkeypatch):
    """MAVProxy and the like: the wall clock once a peer spoke and acknowledged nothing."""
    monkeypatch.setattr(sim_clock, "LOCKSTEP_TIMEOUT", 0.05)
    clock = SimClock(0.002, speedup=1.0, lockstep=True)
    clock.start()
    clock.frame_sent(LOCKSTEP_FRAME_US)
    time.sleep(0.06)
    assert clock.held  # no peer heard: no time-out
    clock.heard_peer()
    assert clock.held
    time.sleep(0.06)
    assert not clock.held and not clock.starting
    clock.frame_sent(2 * LOCKSTEP_FRAME_US)
    assert not clock.held  # the wall clock from now on
    assert clock.stats().lockstep_timeouts == 1
    clock.acknowledge(2 * LOCKSTEP_FRAME_US)  # a lock-step peer after all
    assert clock.engaged


def test_held_frame_is_sent_again(monkeypatch):
    monkeypatch.setattr(sim_clock, "LOCKSTEP_RESEND", 0.02)
    clock = SimClock(0.002, lockstep=True)
    clock.start()
    clock.frame_sent(LOCKSTEP_FRAME_US)
    assert clock.resend_due() is None  # just sent
    time.sleep(0.03)
    assert clock.resend_due() == LOCKSTEP_FRAME_US and clock.resend_due() is None
    clock.acknowledge(LOCKSTEP_FRAME_US)
    time.sleep(0.03)
    assert clock.resend_due() is None


def test_unacknowledged_frame_falls_back_to_the_wall_clock(monkeypatch):
    monkeypatch.setattr(sim_clock, "LOCKSTEP_TIMEOUT", 0.05)
    clock = SimClock(0.002, speedup=1.0, lockstep=True)
    clock.start()
    clock.acknowledge(LOCKSTEP_FRAME_US)
    clock.frame_sent(2 * LOCKSTEP_FRAME_US)
    assert clock.held
    time.sleep(0.06)
    assert not clock.held and not clock.engaged
    assert clock.stats().lockstep_timeouts == 1
    clock.acknowledge(2 * LOCKSTEP_FRAME_US)  # the peer is back
    assert clock.engaged


def test_without_lockstep_acknowledgements_are_ignored():
    clock = SimClock(0.002, lockstep=False)
    clock.start()
    assert not clock.frame_due(LOCKSTEP_FRAME_US)
    clock.acknowledge(LOCKSTEP_FRAME_US)
    clock.frame_sent(2 * LOCKSTEP_FRAME_US)
    assert not clock.held


def test_streamer_clock_is_the_vehicle_time_and_acknowledges_once():
    clock = LinkClock(speedup=1.0, lockstep=True)
    time.sleep(0.02)
    assert clock.now() == 0.0  # stands until the first frame, as the held vehicle does
    clock.observe(_frame(5000))
    assert clock.now() == 5.0
    time.sleep(0.05)  # wall time passes, vehicle time does not
    assert clock.now() == 5.0
    clock.observe(_frame(5250))
    assert clock.now() == 5250 / 1000  # the frame's time to the bit, whatever came before
    assert clock.take_ack() == 5250 and clock.take_ack() is None
    clock.observe(_frame(5250, unix_us=0))  # an ordinary SYSTEM_TIME: ignored
    assert clock.take_ack() is None and clock.frames == 2


def test_streamer_clock_stamps_receipt_no_earlier_than_sent():
    """Telemetry of the ticks a frame closes arrives before that frame: it is stamped with
    its own time (as received over a real link), while `now` stays at the last frame."""
    clock = LinkClock(speedup=1.0, lockstep=True)
    clock.observe(_frame(5000))
    attitude = M.MAVLink_attitude_message(5008, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    attitude.pack(M.MAVLink(None, srcSystem=1))
    clock.observe(attitude)
    assert clock.now() == 5.0 and clock.received(attitude) == 5008 / 1000
    old = M.MAVLink_attitude_message(4990, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    old.pack(M.MAVLink(None, srcSystem=1))
    assert clock.received(old) == 5.0
    wall = LinkClock(speedup=1.0)  # without lock-step: the clock alone
    assert wall.received(attitude) == pytest.approx(wall.now(), abs=0.01)


def test_streamer_clock_runs_when_a_vehicle_sends_no_frames(monkeypatch):
    """A vehicle that speaks but sends no frames (no lock-step): the wall clock after
    `FRAME_GRACE`; nothing heard at all: after `START_GRACE`."""
    monkeypatch.setattr(link_clock, "FRAME_GRACE", 0.02)
    monkeypatch.setattr(link_clock, "START_GRACE", 0.2)
    silent, spoken = LinkClock(lockstep=True), LinkClock(lockstep=True)
    spoken.observe(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3))
    time.sleep(0.06)
    assert silent.now() == 0.0 and spoken.now() > 0.03
    time.sleep(0.2)
    assert silent.now() > 0.0


def test_streamer_clock_goes_on_when_frames_stop(monkeypatch):
    monkeypatch.setattr(link_clock, "FRAME_GRACE", 0.02)
    clock = LinkClock(speedup=2.0, lockstep=True)
    clock.observe(_frame(1000))
    t0 = clock.now()
    time.sleep(0.12)
    assert clock.now() > t0 + 0.1  # (0.12 − 0.02) s wall × 2
    later = clock.now()
    clock.observe(_frame(1010))  # frames again: never backwards
    assert clock.now() >= later
    clock.observe(_frame(1000))  # a late repeat of an older frame: ignored
    assert clock.now() >= later


def test_streamer_clock_without_lockstep_ignores_frames():
    clock = LinkClock(speedup=1.0)
    clock.observe(_frame(5000))
    assert clock.take_ack() is None and clock.frames == 0


def _fly(work: Path, trajectory: Path, busy: int) -> tuple[dict, np.ndarray]:
    """`mavsysid stream --lockstep` against `mavsysid sim --lockstep` with ``busy`` busy
    processes running meanwhile; the streamer's meta.json and the pose log's t, x, y, z."""
    hogs = [subprocess.Popen(["sh", "-c", "while :; do :; done"]) for _ in range(busy)]
    try:
        port = free_udp_port()
        with SimProcess(work / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                        "4", "--seed", "7") as sim:
            result = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup",
                                "4", "--log-dir", str(work / "logs"), cwd=work, timeout=600)
            assert result.returncode == 0, result.stderr + sim.output()
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    directory = flight_dir(work / "logs")
    log = read_pose_log(directory / "pose.csv", 6)
    return (json.loads((directory / "meta.json").read_text()),
            np.column_stack([log.t, log.position]))


@pytest.mark.slow
def test_same_flight_idle_and_under_load(tmp_path):
    """The same lock-step flight (sensor noise on, seeded) idle and with `BUSY` busy
    processes on the cores: the same samples, the same poses, the same tracking."""
    trajectory = export_excitation(tmp_path / "figure.json", 10.0)
    (tmp_path / "idle").mkdir()
    (tmp_path / "loaded").mkdir()
    idle_meta, idle = _fly(tmp_path / "idle", trajectory, 0)
    loaded_meta, loaded = _fly(tmp_path / "loaded", trajectory, BUSY)
    print(f"idle: {idle_meta['samples']} samples, tracking {idle_meta['tracking']}; loaded: "
          f"{loaded_meta['samples']} samples, tracking {loaded_meta['tracking']}")
    assert idle_meta["samples"] == loaded_meta["samples"] == len(idle) == len(loaded)
    assert idle_meta["setpoints"]["sent"] == loaded_meta["setpoints"]["sent"]
    assert np.max(np.abs(idle - loaded)) < 1e-4  # s and m: the same timeline and path
    for key in ("rms_m", "max_m"):
        assert abs(idle_meta["tracking"][key] - loaded_meta["tracking"][key]) < 1e-4
