"""Flying `mavsysid stream` against `mavsysid sim`, both as real processes on UDP loopback.

Helpers for the end-to-end and fault tests: export a built-in excitation figure as a
trajectory file, start the simulated vehicle, run or start the streamer, find the flight
directory, and read a tlog back with pymavlink.

Both sides run in **lock-step** by default (``mavsysid sim --lockstep``, ``mavsysid stream
--lockstep``): they share the vehicle's sim time, so a flight gives the same samples and
tracking on an idle or an overloaded machine. ``lockstep=False`` keeps the wall clock,
for the few tests of the real-time path.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.vehicle.config import load_vehicle

__all__ = [
    "BOX",
    "SimProcess",
    "export_excitation",
    "flight_dir",
    "read_all_parameters",
    "read_parameters",
    "read_tlog",
    "run_mavsysid",
    "run_stream",
    "start_stream",
    "wait_for",
]

#: The flight box of the tests, m (the excitation figure spans x ±1.3, y ±1, z 1.1–1.9).
BOX = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)
_REPO = Path(__file__).resolve().parents[2]
_ENV = {**os.environ, "PYTHONPATH": str(_REPO), "PYTHONUNBUFFERED": "1"}


def _mavsysid(*args: str) -> list[str]:
    return [sys.executable, "-m", "mavsysid", *args]


def export_excitation(path: Path, duration: float, box: Sequence[float] | None = BOX,
                      vehicle: str = "firefly") -> Path:
    """Write the built-in excitation figure of ``duration`` s as a trajectory file."""
    trajectory = excitation_trajectory(ExcitationSpec(duration=duration))
    write_trajectory_file(path, trajectory_file_for(trajectory, load_vehicle(vehicle),
                                                    box=None if box is None else tuple(box)))
    return path


class SimProcess:
    """``mavsysid sim ARGS`` in its own process; its output goes to files in ``directory``.

    ``lockstep`` (default) adds ``--lockstep``: the sim holds at its first frame until a
    lock-step streamer acknowledges it (however late that connects), and runs on the wall
    clock 2 s after a peer that acknowledges nothing (MAVProxy, MAVSDK) first spoke.
    """

    def __init__(self, directory: Path, *args: str, lockstep: bool = True) -> None:
        args = (*args, "--lockstep") if lockstep else args
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.stdout_path = self.directory / "sim.out"
        self.stderr_path = self.directory / "sim.err"
        with open(self.stdout_path, "wb") as out, open(self.stderr_path, "wb") as err:
            self.process = subprocess.Popen(_mavsysid("sim", *args), stdout=out, stderr=err,
                                            env=_ENV, cwd=self.directory)

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Wait until the sim says it runs (its banner)."""
        wait_for(lambda: "Ctrl-C to stop" in self.output(), timeout, "the sim to start")

    def output(self) -> str:
        """What the sim printed so far (stdout, then stderr)."""
        return (self.stdout_path.read_text(errors="replace")
                + self.stderr_path.read_text(errors="replace"))

    def kill(self) -> None:
        """SIGKILL (a crashed vehicle link)."""
        self.process.kill()
        self.process.wait(timeout=10)

    def stop(self) -> str:
        """Stop with SIGINT as a user would; returns its stdout and stderr."""
        if self.process.poll() is None:
            self.process.send_signal(2)
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=10)
        return self.output()

    def __enter__(self) -> SimProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _operator_box(args: Sequence[str]) -> tuple[str, ...]:
    """``--box`` with the tests' `BOX`, unless the arguments give a box or a vehicle file
    (whose ``[flight] box`` is then the operator's)."""
    if "--box" in args or "--vehicle" in args:
        return ()
    return ("--box", ",".join(f"{b:g}" for b in BOX))


def run_stream(trajectory: Path, *args: str, cwd: Path, timeout: float = 180.0,
               lockstep: bool = True) -> subprocess.CompletedProcess[str]:
    """``mavsysid stream TRAJECTORY ARGS`` to completion, output captured (lock-step; the
    operator's box is `BOX` unless ARGS give ``--box`` or ``--vehicle``)."""
    args = (*args, *_operator_box(args))
    args = (*args, "--lockstep") if lockstep else args
    return subprocess.run(_mavsysid("stream", str(trajectory), *args), capture_output=True,
                          text=True, env=_ENV, cwd=cwd, timeout=timeout, check=False)


def start_stream(trajectory: Path, *args: str, cwd: Path,
                 lockstep: bool = True) -> subprocess.Popen[str]:
    """``mavsysid stream TRAJECTORY ARGS`` started (lock-step, box as in `run_stream`);
    stderr to ``cwd/stream.err``."""
    args = (*args, *_operator_box(args))
    args = (*args, "--lockstep") if lockstep else args
    err = open(cwd / "stream.err", "w")  # noqa: SIM115 - the child keeps it open
    return subprocess.Popen(_mavsysid("stream", str(trajectory), *args), stdout=subprocess.PIPE,
                            stderr=err, text=True, env=_ENV, cwd=cwd)


def flight_dir(log_dir: Path) -> Path:
    """The one flight directory under ``log_dir``."""
    (found,) = [p for p in Path(log_dir).iterdir() if p.is_dir()]
    return found


def wait_for(condition: Callable[[], Any], timeout: float, what: str) -> Any:
    """Poll ``condition`` every 50 ms until it is truthy; fail the test after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


def read_tlog(path: Path) -> list[tuple[float, Any]]:
    """(record stamp s, message) of every record of a tlog, read by pymavlink."""
    log = load_mavutil().mavlink_connection(str(path))
    out = []
    while (m := log.recv_match()) is not None:
        if m.get_type() != "BAD_DATA":
            out.append((m._timestamp, m))
    log.close()
    return out


def run_mavsysid(*args: str, cwd: Path, timeout: float = 120.0
                 ) -> subprocess.CompletedProcess[str]:
    """``mavsysid ARGS`` to completion, output captured."""
    return subprocess.run(_mavsysid(*args), capture_output=True, text=True, env=_ENV, cwd=cwd,
                          timeout=timeout, check=False)


def read_parameters(port: int, names: Sequence[str], timeout: float = 30.0
                    ) -> dict[str, float]:
    """Parameter values read with pymavlink alone from a vehicle sending to 127.0.0.1:PORT
    (``mavsysid sim --connect udpout:127.0.0.1:PORT``), independently of mavsysid's
    ground station; an ArduPilot-style vehicle (values carried as floats)."""
    mavutil = load_mavutil()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=254)
    try:
        if conn.wait_heartbeat(timeout=timeout) is None:
            raise AssertionError(f"no heartbeat on 127.0.0.1:{port}")
        values: dict[str, float] = {}
        deadline = time.monotonic() + timeout
        while len(values) < len(names) and time.monotonic() < deadline:
            for name in names:
                if name not in values:
                    conn.mav.param_request_read_send(conn.target_system, conn.target_component,
                                                     name.encode("ascii"), -1)
            end = time.monotonic() + 1.0
            while time.monotonic() < end and len(values) < len(names):
                m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
                if m is not None:
                    pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
                    values[pid.rstrip("\0")] = float(m.param_value)
        return values
    finally:
        conn.close()


def read_all_parameters(port: int, timeout: float = 30.0) -> dict[str, float]:
    """Every parameter of a vehicle sending to 127.0.0.1:PORT (PARAM_REQUEST_LIST), read
    with pymavlink alone, as `read_parameters`."""
    mavutil = load_mavutil()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=254)
    try:
        if conn.wait_heartbeat(timeout=timeout) is None:
            raise AssertionError(f"no heartbeat on 127.0.0.1:{port}")
        values: dict[str, float] = {}
        count = None
        deadline = time.monotonic() + timeout
        while (count is None or len(values) < count) and time.monotonic() < deadline:
            conn.mav.param_request_list_send(conn.target_system, conn.target_component)
            end = time.monotonic() + 2.0
            while time.monotonic() < end and (count is None or len(values) < count):
                m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
                if m is not None:
                    pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
                    values[pid.rstrip("\0")] = float(m.param_value)
                    count = m.param_count
        if count is None or len(values) < count:
            raise AssertionError(f"read {len(values)} of {count} parameters")
        return values
    finally:
        conn.close()
