"""ArduCopter SITL (``../shared/sitl/arducopter``) as a test peer, on loopback only.

`running_sitl` starts the real ArduPilot Copter firmware in a scratch directory on a free
instance number, waits until its MAVLink TCP server listens on 127.0.0.1, and always kills
it (and only it, by PID) on the way out. A test that needs it is skipped when the binary is
absent or not executable (CI without ``../shared``).
"""

from __future__ import annotations

import os
import socket
import subprocess
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from mavsysid.flight.mavlink_setup import load_mavutil

from tests.support.stream_flights import start_stream, wait_for

__all__ = ["SITL_DIR", "Observer", "SitlInstance", "gentle_trajectory", "observing",
           "require_sitl", "running_sitl",
           "streaming"]

#: Where the shared SITL build lives, beside the checkout.
SITL_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "sitl"
#: Instance N listens on 5760 + 10 N (SERIAL0) and 5762 + 10 N (SERIAL1).
_BASE_PORT = 5760
_PORT_STEP = 10
#: Instances tried, spread so that parallel tests and people rarely collide.
_INSTANCES = range(3, 40)
#: Home: the README's, a field near Zurich (lat, lon, alt m, heading deg).
_HOME = "47.397,8.545,488,0"


@dataclass(frozen=True)
class SitlInstance:
    """A running SITL: its instance number, MAVLink TCP port, scratch directory, PID."""

    instance: int
    port: int
    directory: Path
    pid: int

    @property
    def connect(self) -> str:
        """The ``--connect`` string for ``mavsysid stream``."""
        return f"tcp:127.0.0.1:{self.port}"

    def output(self) -> str:
        """What SITL printed so far."""
        path = self.directory / "sitl.out"
        return path.read_text(errors="replace") if path.exists() else ""


def gentle_trajectory(path: Path, vehicle: str, box: tuple[float, ...]) -> Path:
    """Write a gentle 10 s excitation for ``vehicle`` inside ``box`` to ``path``; the path."""
    from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
    from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
    from mavsysid.vehicle.config import load_vehicle

    gentle = excitation_trajectory(ExcitationSpec(duration=10.0, amplitude=(0.8, 0.6, 0.3)))
    write_trajectory_file(path, trajectory_file_for(gentle, load_vehicle(vehicle), box=box))
    return path


def require_sitl() -> Path:
    """The SITL binary, or skip the calling test if it is absent or not executable."""
    binary = SITL_DIR / "arducopter"
    if not binary.is_file() or not os.access(binary, os.X_OK):
        pytest.skip(f"no executable ArduCopter SITL at {binary}")
    return binary.resolve()


def _port_free(port: int) -> bool:
    """Whether 127.0.0.1:port can be bound (SO_REUSEADDR: only a listener blocks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
        return True


def _free_instance() -> int:
    """An instance number whose two TCP ports are free on 127.0.0.1 right now."""
    for n in _INSTANCES:
        port = _BASE_PORT + _PORT_STEP * n
        if _port_free(port) and _port_free(port + 2):
            return n
    pytest.skip("no free ArduCopter SITL instance (all its loopback ports are taken)")


def _listening(port: int) -> bool:
    """Whether something listens on 127.0.0.1:port, checked without connecting (SITL's
    SERIAL0 serves one client, which must be the streamer)."""
    return not _port_free(port)


@contextmanager
def running_sitl(scratch: Path, defaults: Sequence[Path] = (), model: str = "quad",
                 timeout: float = 30.0, speedup: float = 1.0) -> Iterator[SitlInstance]:
    """Run ArduCopter SITL for the ``with`` block.

    Parameters
    ----------
    scratch : Path
        An empty directory; SITL writes ``eeprom.bin``, ``logs/`` and ``sitl.out`` there.
    defaults : sequence of Path
        Parameter files loaded after ``copter.parm``, later ones winning.
    model : str
        SITL's physics frame (``quad`` is "+", ``x`` is X).
    timeout : float
        How long to wait for its TCP server, s (wall time).
    speedup : float
        SITL's ``--speedup`` (simulated time per wall second; the streamer then needs the
        same ``--speedup``).

    Yields
    ------
    SitlInstance
        Listening, not yet ready to arm (that takes about 25 s more: the streamer waits).
    """
    binary = require_sitl()
    scratch.mkdir(parents=True, exist_ok=True)
    instance = _free_instance()
    port = _BASE_PORT + _PORT_STEP * instance
    parms = ",".join(str(p.resolve()) for p in [SITL_DIR / "copter.parm", *defaults])
    with open(scratch / "sitl.out", "wb") as out:
        process = subprocess.Popen(
            [str(binary), "-w", "--model", model, "--speedup", f"{speedup:g}", "--defaults",
             parms, f"-I{instance}", "--home", _HOME, "--sim-address=127.0.0.1"],
            cwd=scratch, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + timeout
        while not _listening(port):
            if process.poll() is not None:
                raise AssertionError(f"SITL exited with {process.returncode}:\n"
                                     + (scratch / "sitl.out").read_text(errors="replace"))
            if time.monotonic() > deadline:
                raise AssertionError(f"SITL did not listen on 127.0.0.1:{port} "
                                     f"within {timeout:g} s")
            time.sleep(0.1)
        yield SitlInstance(instance, port, scratch, process.pid)
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=10)


class Observer:
    """A second ground station on SITL's SERIAL1 (system 254)."""

    def __init__(self, port: int) -> None:
        # SITL opens SERIAL1 once its SERIAL0 client (the streamer) has connected.
        self.conn = wait_for(lambda: self._connect(port), 60.0, "SITL's second port")
        if self.conn.wait_heartbeat(timeout=30) is None:
            raise AssertionError("no heartbeat on SITL's second port")
        self.conn.mav.command_long_send(1, 1, 511, 0, 32, 1e5, 0, 0, 0, 0, 0)  # LPN 10 Hz

    @staticmethod
    def _connect(port: int) -> Any:
        try:
            return load_mavutil().mavlink_connection(
                f"tcp:127.0.0.1:{port}", source_system=254, source_component=190, retries=1)
        except OSError:
            return None

    def drain(self) -> None:
        """Drop what arrived unread (older PARAM_VALUEs would pass for fresh answers)."""
        while self.conn.recv_match(blocking=False) is not None:
            pass

    def params(self, names: tuple[str, ...], timeout: float = 10.0) -> dict[str, float]:
        """The values of ``names`` now (those answered within ``timeout`` s)."""
        self.drain()
        got: dict[str, float] = {}
        deadline = time.monotonic() + timeout
        while len(got) < len(names) and time.monotonic() < deadline:
            for name in names:
                if name not in got:
                    self.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
            end = time.monotonic() + 1.0
            while time.monotonic() < end:
                m = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
                if m is not None and m.param_id in names:
                    got[m.param_id] = m.param_value
        return got

    def position(self, timeout: float = 5.0) -> Any:
        return self.conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=timeout)

    def close(self) -> None:
        self.conn.close()


@contextmanager
def observing(sitl: SitlInstance) -> Iterator[Observer]:
    """An `Observer` on ``sitl``'s SERIAL1 for the ``with`` block, closed on the way out."""
    observer = Observer(sitl.port + 2)
    try:
        yield observer
    finally:
        observer.close()


@contextmanager
def streaming(trajectory: Path, sitl: SitlInstance, *args: str, cwd: Path
              ) -> Iterator[subprocess.Popen[str]]:
    """``mavsysid stream`` of ``trajectory`` to ``sitl`` (wall clock: a real autopilot) for
    the ``with`` block, stderr in ``cwd/stream.err``; killed on the way out if still running."""
    stream = start_stream(trajectory, "--connect", sitl.connect, *args, cwd=cwd, lockstep=False)
    try:
        yield stream
    finally:
        if stream.poll() is None:
            stream.kill()
        stream.wait(timeout=10)
        if stream.stdout is not None:
            stream.stdout.close()
