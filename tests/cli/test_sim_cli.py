"""Tests of ``mavsysid sim`` as a real process: signals, the truth log, option errors.

Its pacing is tested on a simulated wall clock (``tests/flight/simvehicle/test_sim_parts.py``),
which no load can disturb; ``bench/stream_timing.py`` runs the process at speedup 1 in real
time.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.simvehicle.link import mavlink as M
from mavsysid.flight.simvehicle.link import mavutil
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.rotation import quat_conjugate, quat_log, quat_multiply

ROOT = Path(__file__).resolve().parents[2]


def _gcs():
    link = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255,
                                      source_component=190)
    return link, link.port.getsockname()[1]


def _start(port: int, *options: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "mavsysid", "sim", "--connect", f"udpout:127.0.0.1:{port}",
         *options], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _first_heartbeat(link, process: subprocess.Popen):
    hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=60)
    if hb is None:
        process.kill()
        raise AssertionError(f"no heartbeat; stderr: {process.communicate()[1]}")
    return hb


def _command(link, command: int, *params: float, timeout: float = 2.0):
    p = list(params) + [0.0] * (7 - len(params))
    link.mav.command_long_send(1, 1, command, 0, *p)
    ack = link.recv_match(type="COMMAND_ACK", blocking=True, timeout=timeout,
                          condition=f"COMMAND_ACK.command=={command}")
    return None if ack is None else ack.result


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
@pytest.mark.slow
def test_signal_closes_the_truth_log_and_reports_rejected_signatures(tmp_path, signum):
    """SIGTERM/SIGINT: exit 0 with a one-line summary counting rejected signatures; the
    truth log holds truth.csv (true state and rotor speeds at 200 Hz), pose.csv (the noisy
    pose) and meta.json (status complete, true θ with --theta-scale, the counts)."""
    key_file = tmp_path / "key.txt"
    key_file.write_text("correct horse battery staple\n")
    truth_dir = tmp_path / "truth"
    link, port = _gcs()
    sim = _start(port, "--speedup", "4", "--ekf-delay", "0", "--truth-log", str(truth_dir),
                 "--signing-key", str(key_file), "--theta-scale", "1.1,1,1,1,1.2,1",
                 "--seed", "3")
    try:
        _first_heartbeat(link, sim)
        # Unsigned: ignored and counted.
        assert _command(link, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=0.5) is None
        link.setup_signing(hashlib.sha256(b"correct horse battery staple").digest(),
                           sign_outgoing=True)
        assert _command(link, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        time.sleep(0.5)
        sim.send_signal(signum)
        out, err = sim.communicate(timeout=30)
    finally:
        if sim.poll() is None:
            sim.kill()
        link.close()
    assert sim.returncode == 0, err
    lines = out.strip().splitlines()
    assert lines[-1].startswith("mavsysid sim: stopped after")
    assert "rejected signatures 1 (1 unsigned, 0 bad; 1 commands, 0 setpoints)" in lines[-1]

    meta = read_meta(truth_dir / "meta.json")
    assert meta["status"] == "complete"
    assert meta["simulated"] is True
    nominal = load_vehicle("firefly").parameters
    assert meta["truth"]["parameters"]["c_T"] == pytest.approx(1.1 * nominal.c_T)
    assert meta["truth"]["parameters"]["j_y"] == pytest.approx(1.2 * nominal.J[1])
    assert meta["summary"]["rejected_signatures"]["commands"] == 1
    truth = read_pose_log(truth_dir / "truth.csv", 6)
    pose = read_pose_log(truth_dir / "pose.csv", 6)
    assert len(truth) == len(pose) == meta["samples"] > 200
    np.testing.assert_allclose(np.diff(truth.t), 0.005, atol=1e-6)
    assert truth.t[0] == 0.0
    # Armed on the ground: the rotors idle, and the log has the lagged actual speeds.
    assert truth.rotor_speeds[-1].min() > 50.0
    assert np.all(truth.rotor_speeds[0] == 0.0)
    err_p = pose.position - truth.position
    err_q = quat_log(quat_multiply(quat_conjugate(truth.quaternion), pose.quaternion))
    assert np.std(err_p) == pytest.approx(0.0005, rel=0.15)
    assert np.std(err_q) == pytest.approx(np.radians(0.1), rel=0.15)


@pytest.mark.parametrize(("options", "message"), [
    (["--speedup", "0"], "--speedup 0"),
    (["--connect", "serial:/dev/mavsysid-no-such-device:57600"],
     "--connect 'serial:/dev/mavsysid-no-such-device:57600'"),
    (["--connect", "udp:127.0.0.1:14550"], "udp:/tcp: are ground-station forms"),
    (["--connect", "bluetooth:1"], "expected udpout:HOST:PORT"),
    (["--fault", "explode"], "--fault 'explode'"),
    (["--theta-scale", "1,2"], "--theta-scale"),
    (["--signing-key", "/nonexistent/key"], "--signing-key"),
    (["--fault", "mode:NOPE@3"], "unknown ardupilot mode NOPE"),
    (["--hidden-effect", "motor_lag:tau=0.04", "--hidden-effect", "windy:x=2"],
     "--hidden-effect 'windy:x=2': unknown effect 'windy'; expected one of body_drag,"),
    (["--hidden-effect", "wind:z=2"], "unknown parameter 'z'; expected one of x, y"),
])
def test_bad_options_exit_2_with_one_line(options, message):
    """Malformed options are refused with exit code 2 and one line, before anything runs."""
    cmd = [sys.executable, "-m", "mavsysid", "sim", *options]
    if "--connect" not in options:
        cmd += ["--connect", "udpout:127.0.0.1:9"]
    result = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60,
                            env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1
    assert message in result.stderr
