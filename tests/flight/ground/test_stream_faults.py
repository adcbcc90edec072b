"""Faults during a streamed flight: `mavsysid stream` and `mavsysid sim` as real processes.

The sim runs faster than real time (--speedup on both sides) to keep these short.
"""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log

from tests.support.stream_flights import (
    SimProcess,
    export_excitation,
    flight_dir,
    read_tlog,
    run_stream,
    start_stream,
    wait_for,
)

pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore::UserWarning")]

SPEEDUP = "8"


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory) -> Path:
    """A 12 s excitation figure inside the test box."""
    return export_excitation(tmp_path_factory.mktemp("traj") / "figure12.json", 12.0)


def _last_row(pose: Path) -> list[float] | None:
    """The last complete row of a pose log being written (None before the first)."""
    try:
        lines = pose.read_text().split("\n")
    except FileNotFoundError:
        return None
    rows = [line for line in lines[1:-1] if line]  # the last element may be half a row
    return [float(x) for x in rows[-1].split(",")] if rows else None


def _in_trajectory(logs: Path, after: float) -> bool:
    """Whether the flight in ``logs`` has flown ``after`` s of its trajectory."""
    pose = [p / "pose.csv" for p in logs.glob("*") if p.is_dir()]
    row = _last_row(pose[0]) if pose else None
    return row is not None and row[-1] >= after  # t_traj is the last column


def _stream_args(port: int, logs: Path, connect: str = "udp") -> list[str]:
    return ["--connect", f"{connect}:127.0.0.1:{port}", "--speedup", SPEEDUP, "--log-dir",
            str(logs)]


def _finished(process, timeout: float) -> int:
    return process.wait(timeout=timeout)


def test_killed_streamer_keeps_its_logs(tmp_path, trajectory):
    """SIGKILL mid-flight: pose.csv and flight.tlog read back up to < 1 s before the kill."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, "--truth-log", str(tmp_path / "truth")):
        stream = start_stream(trajectory, *_stream_args(port, logs), cwd=tmp_path)
        wait_for(lambda: _in_trajectory(logs, 4.0), 60, "4 s of trajectory")
        # The sim's truth log (flushed per row, sim time) tells when the kill happened.
        kill_time = _last_row(tmp_path / "truth" / "truth.csv")[0]
        stream.send_signal(signal.SIGKILL)
        stream.wait(timeout=10)
    directory = flight_dir(logs)
    log = read_pose_log(directory / "pose.csv", 6)
    assert kill_time - 1.0 < log.t[-1] < kill_time + 2.0  # (the kill follows the reading)
    positions = [m for _, m in read_tlog(directory / "flight.tlog")
                 if m.get_type() == "LOCAL_POSITION_NED"]
    assert positions[-1].time_boot_ms * 1e-3 > kill_time - 1.0
    assert len(positions) >= len(log)
    # The live meta.json reads as aborted with no clean-up, the count ~1 s behind at most.
    meta = read_meta(directory / "meta.json")
    assert meta["status"] == "aborted" and meta["running"] is True
    assert "killed" in meta["reason"]
    assert len(log) - 75 <= meta["samples"] <= len(log)  # 1 s at 50 Hz, plus slack


def test_vehicle_heartbeat_loss_stops_the_stream(tmp_path, trajectory):
    """The sim dies mid-flight: the streamer stops its setpoints within the 3 s heartbeat
    limit (its own clock), reports the lost heartbeat and exits 3."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    sim = SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                     SPEEDUP)
    try:
        stream = start_stream(trajectory, *_stream_args(port, logs), cwd=tmp_path)
        wait_for(lambda: _in_trajectory(logs, 2.0), 60, "2 s of trajectory")
        sim.kill()
        code = _finished(stream, 60)
    finally:
        sim.stop()
    error = (tmp_path / "stream.err").read_text()
    assert code == 3
    assert "heartbeat lost" in error and "left to its own failsafe" in error
    # On the streamer's own clock (the tlog's stamps), which no load can stretch: no
    # setpoint goes out 3 s (the heartbeat-loss limit) after the vehicle's last heartbeat.
    # A received message is stamped when written, up to a lock-step frame (10 ms) before
    # the receipt time the check uses.
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    last_beat = max(t for t, m in records
                    if m.get_type() == "HEARTBEAT" and m.get_srcSystem() != 255)
    last_setpoint = max(t for t, m in records
                        if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED")
    assert 0.0 < last_setpoint - last_beat < 3.0 + 0.02
    meta = read_meta(flight_dir(logs) / "meta.json")
    assert meta["status"] == "aborted" and "heartbeat lost" in meta["reason"]


def test_link_loss_is_seen_within_1_5_s_in_real_time(tmp_path, trajectory):
    """WALL CLOCK on purpose, no speedup (the real-time path): the sim is killed
    mid-trajectory; the streamer sees the loss
    within 1.5 s of the vehicle's last message (the tlog's clock) and sends no setpoint
    after it: only those of the ~1 s link-loss limit follow the last vehicle message."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    sim = SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}",
                     lockstep=False)
    try:
        stream = start_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--log-dir",
                              str(logs), cwd=tmp_path, lockstep=False)
        wait_for(lambda: _in_trajectory(logs, 1.0), 120, "1 s of trajectory")
        sim.kill()
        code = _finished(stream, 20)
    finally:
        sim.stop()
    assert code == 3
    assert "no message at all from the vehicle" in (tmp_path / "stream.err").read_text()
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    assert any(m.get_type() == "COMMAND_LONG" and m.command == 511 and m.param1 == 36
               for _, m in records)  # SERVO_OUTPUT_RAW asked for, for the motor outputs
    last_heard = max(t for t, m in records if m.get_srcSystem() == 1)
    after = [t for t, m in records
             if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and t > last_heard]
    assert after and after[-1] - last_heard <= 1.0 + 0.03  # stopped at the limit
    assert len(after) <= 52  # 1 s at 50 Hz
    meta = read_meta(flight_dir(logs) / "meta.json")
    seen_after = float(meta["reason"].split(" for ")[1].split(" s")[0])
    assert seen_after <= 1.5 and meta["running"] is False


def test_pilot_mode_change_stops_the_stream_at_once(tmp_path, trajectory):
    """A third client switches to LOITER mid-flight: no setpoint is sent after the streamer
    hears of it, it exits 3 naming the mode, and sends no command of its own."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    mavutil = load_mavutil()
    with SimProcess(tmp_path / "sim", "--connect", f"udpin:127.0.0.1:{port}", "--speedup",
                    SPEEDUP):
        stream = start_stream(trajectory, *_stream_args(port, logs, "udpout"), cwd=tmp_path)
        pilot = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=250,
                                           source_component=190)
        try:
            wait_for(lambda: _in_trajectory(logs, 3.0), 60, "3 s of trajectory")
            pilot.mav.command_long_send(1, 1, 176, 0, 1, ARDUCOPTER_MODES["LOITER"],
                                        0, 0, 0, 0, 0)
            code = _finished(stream, 20)
        finally:
            pilot.close()
    error = (tmp_path / "stream.err").read_text()
    assert code == 3
    assert "flight mode changed from GUIDED to LOITER" in error
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    heard = min(t for t, m in records if m.get_type() == "HEARTBEAT"
                and m.get_srcSystem() == 1 and m.custom_mode == ARDUCOPTER_MODES["LOITER"])
    ours_after = [m.get_type() for t, m in records if t > heard and m.get_srcSystem() == 255]
    assert "SET_POSITION_TARGET_LOCAL_NED" not in ours_after
    assert "COMMAND_LONG" not in ours_after
    setpoints = [t for t, m in records if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert heard - setpoints[-1] < 0.1  # it was streaming until then (streamer seconds)


def test_refused_arm_reports_the_result(tmp_path, trajectory):
    """The vehicle refuses to arm: exit 3 naming MAV_RESULT_DENIED; nothing flew."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, "--fault", "deny-arm"):
        result = run_stream(trajectory, *_stream_args(port, logs), cwd=tmp_path, timeout=60)
    assert result.returncode == 3
    assert "error: arm refused by the vehicle: MAV_RESULT_DENIED" in result.stderr
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    arms = [m for _, m in records if m.get_type() == "COMMAND_LONG" and m.command == 400]
    acks = [m for _, m in records if m.get_type() == "COMMAND_ACK" and m.command == 400]
    assert len(arms) == 1 and acks[0].result == 2  # DENIED is not retried
    assert not any(m.get_type() == "COMMAND_LONG" and m.command == 22 for _, m in records)
    meta = read_meta(flight_dir(logs) / "meta.json")
    assert meta["status"] == "aborted" and "MAV_RESULT_DENIED" in meta["reason"]


def test_out_of_box_trajectory_is_refused_before_anything_is_sent(tmp_path, trajectory):
    """A trajectory leaving the box is refused with the reason (exit 3) before connecting:
    no flight directory, no tlog, and so no arm command."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP) as sim:
        sim.wait_ready()
        result = run_stream(trajectory, *_stream_args(port, logs), "--box",
                            "-2,-2,0.5,2,2,1.5", cwd=tmp_path, timeout=60)
        sim_output = sim.stop()
    assert result.returncode == 3
    line, = result.stderr.strip().splitlines()
    assert line.startswith("mavsysid stream: error: flight refused: the trajectory leaves "
                           "the box [-2,-2,0.5,2,2,1.5] at t = 0.00 s (z = 1.900 m")
    assert not logs.exists()
    assert " 0 messages in" in sim_output


def test_vehicle_beside_the_box_is_refused_before_arming(tmp_path, trajectory):
    """A vehicle standing outside the box's footprint: refused after connecting, with the
    reason; the tlog shows no arm command and the vehicle never armed."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, "--start", "3,0.5,0"):
        result = run_stream(trajectory, *_stream_args(port, logs), cwd=tmp_path, timeout=60)
    assert result.returncode == 3
    assert "error: flight refused: the vehicle is at x = 3.00 m" in result.stderr
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    commands = {m.command for _, m in records if m.get_type() == "COMMAND_LONG"}
    assert 400 not in commands and 176 not in commands
    assert commands <= {511, 512}  # message intervals only
    assert not any(m.base_mode & 128 for _, m in records
                   if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1)


def test_wrong_signing_key_is_rejected(tmp_path, trajectory):
    """A signing sim ignores a streamer with another key; the streamer names the cause.

    WALL CLOCK (``lockstep=False``): a lock-step streamer that can read nothing, not even
    a frame, waits `START_GRACE` for one before its clock (and the heartbeat wait) runs."""
    port = free_udp_port()
    (tmp_path / "vehicle.key").write_text("vehicle passphrase\n")
    (tmp_path / "other.key").write_text("some other passphrase\n")
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, "--signing-key", str(tmp_path / "vehicle.key"),
                    lockstep=False) as sim:
        result = run_stream(trajectory, *_stream_args(port, tmp_path / "logs"),
                            "--signing-key", str(tmp_path / "other.key"),
                            "--heartbeat-timeout", "4", cwd=tmp_path, timeout=60,
                            lockstep=False)
        sim_output = sim.stop()
    assert result.returncode == 3
    assert "no vehicle heartbeat" in result.stderr and "wrong signature" in result.stderr
    rejected = int(sim_output.split("rejected signatures ")[1].split()[0])
    assert rejected > 0  # our heartbeats, at least


def test_signed_flight_with_the_right_key(tmp_path, trajectory):
    """With the vehicle's key the flight goes through, every message signed both ways
    (lock-step frames and their acknowledgements included)."""
    port = free_udp_port()
    (tmp_path / "vehicle.key").write_text("vehicle passphrase\n")
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP, "--signing-key", str(tmp_path / "vehicle.key")) as sim:
        result = run_stream(trajectory, *_stream_args(port, logs), "--signing-key",
                            str(tmp_path / "vehicle.key"), cwd=tmp_path, timeout=90)
        sim_output = sim.stop()
    assert result.returncode == 0, result.stderr
    assert "rejected signatures 0 " in sim_output
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    assert all(m.get_header().incompat_flags & 1 for _, m in records)


def test_interrupt_brakes_then_lands(tmp_path, trajectory):
    """Ctrl-C mid-flight: BRAKE, then LAND, then exit 130.

    Lock-step, so that a loaded machine cannot starve the vehicle of setpoints into its
    own failsafe before the interrupt (the interrupt path is the same on the wall clock,
    which `test_link_loss_is_seen_within_1_5_s_in_real_time` flies)."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP):
        stream = start_stream(trajectory, *_stream_args(port, logs), cwd=tmp_path)
        wait_for(lambda: _in_trajectory(logs, 2.0), 60, "2 s of trajectory")
        stream.send_signal(signal.SIGINT)
        code = _finished(stream, 30)
    error = (tmp_path / "stream.err").read_text()
    assert code == 130
    assert "interrupted: mode BRAKE" in error and "interrupted: mode LAND" in error
    records = read_tlog(flight_dir(logs) / "flight.tlog")
    modes = [m.param2 for _, m in records if m.get_type() == "COMMAND_LONG"
             and m.command == 176]
    assert modes[-2:] == [ARDUCOPTER_MODES["BRAKE"], ARDUCOPTER_MODES["LAND"]]
    # In the order sent (under lock-step both can carry the same frame's stamp).
    last_setpoint = max(i for i, (_, m) in enumerate(records)
                        if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED")
    brake = min(i for i, (_, m) in enumerate(records) if m.get_type() == "COMMAND_LONG"
                and m.command == 176 and m.param2 == ARDUCOPTER_MODES["BRAKE"])
    assert last_setpoint < brake
    meta = read_meta(flight_dir(logs) / "meta.json")
    assert meta["status"] == "aborted" and "interrupted" in meta["reason"]


def test_tracking_error_limit_aborts_to_hold(tmp_path, trajectory):
    """Beyond --max-tracking-error the stream stops and the vehicle is put in BRAKE."""
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    SPEEDUP):
        result = run_stream(trajectory, *_stream_args(port, logs), "--max-tracking-error",
                            "0.004", cwd=tmp_path, timeout=60)
    assert result.returncode == 3
    assert "exceeds the limit 0.004 m" in result.stderr
    assert "aborted to BRAKE" in result.stderr
    log = read_pose_log(flight_dir(logs) / "pose.csv", 6)
    assert np.any(log.extra["ref_active"] == 1.0)
