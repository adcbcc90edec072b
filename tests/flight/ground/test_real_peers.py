"""Real ground software against ``mavsysid sim``: headless MAVProxy and MAVSDK-Python.

Each test runs the sim as its own process (``python -m mavsysid sim``) on a free loopback UDP
port, drives the unmodified peer the way a user would, and checks the outcome twice: as the
peer sees it, and in the sim's ground-truth log.
"""

from __future__ import annotations

import asyncio
import csv
import os
import queue
import re
import subprocess
import sys
import threading
import time
from contextlib import aclosing
from pathlib import Path

import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.simvehicle.params import default_parameters
from mavsysid.vehicle.config import load_vehicle

from tests.support.stream_flights import SimProcess

pytestmark = pytest.mark.peers

TAKEOFF_ALTITUDE = 2.0  # m
#: The offboard target, NED from home (m), and how close the vehicle must get to it.
TARGET_NED = (1.0, 0.5, -2.0)
REACHED = 0.2  # m


def _start_sim(tmp_path: Path, port: int, *extra: str,
               lockstep: bool = True) -> tuple[SimProcess, Path]:
    """Start the sim sending to ``127.0.0.1:port`` and wait until it runs (its first start
    compiles the physics, which can take tens of seconds); the process and its truth log."""
    truth = tmp_path / "truth"
    sim = SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                     "1", "--truth-log", str(truth), *extra, lockstep=lockstep)
    try:
        sim.wait_ready(timeout=90.0)
    except BaseException:
        pytest.fail(f"the sim did not start:\n{sim.stop()[-3000:]}")
    return sim, truth


def _truth_positions(truth: Path) -> list[tuple[float, float, float, float]]:
    """(t, x, y, z) ENU rows of the sim's truth log written so far (a partial row is dropped)."""
    path = truth / "truth.csv" if truth.is_dir() else truth
    if not path.exists():
        return []
    with open(path, newline="") as f:
        rows = []
        for row in csv.DictReader(f):
            try:
                rows.append(tuple(float(row[c]) for c in ("t", "x", "y", "z")))
            except (TypeError, ValueError):
                break
    return rows


def _wait_truth(truth: Path, predicate, timeout: float) -> tuple[float, float, float, float]:
    """The first truth row satisfying ``predicate`` (polling the log), or fail after timeout."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        rows = _truth_positions(truth)
        for row in rows:
            if predicate(row):
                return row
        last = rows[-1] if rows else None
        time.sleep(0.25)
    pytest.fail(f"truth never satisfied the condition within {timeout} s; last row {last}")


# -------------------------------------------------------------------------------- MAVProxy


class _MavproxyConsole:
    """MAVProxy run interactively with its stdin and stdout as pipes.

    ``--non-interactive`` would stop it reading stdin; interactive, its command loop is a
    plain ``input()``, so each line written is run as a command. The prompt ("MAV> ",
    "GUIDED> ") is printed without a newline, so replies are matched as substrings.
    """

    def __init__(self, port: int, home: Path) -> None:
        home.mkdir(exist_ok=True)  # no ~/.mavinit.scr, no ~/.mavproxy of the user's
        env = dict(os.environ, PYTHONUNBUFFERED="1", HOME=str(home))
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "MAVProxy.mavproxy", f"--master=udpin:127.0.0.1:{port}",
             "--no-state"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, cwd=home, env=env, bufsize=1)
        self._t0 = time.monotonic()
        self._lines: queue.Queue[str] = queue.Queue()
        self.transcript: list[str] = []  # output lines, and the commands sent
        self._mark = 0  # expect() looks at the transcript from here on
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._lines.put(f"{time.monotonic() - self._t0:6.2f} {line}")

    def send(self, command: str) -> None:
        """Run one MAVProxy command; later `expect` calls look at the output from now on."""
        assert self.proc.stdin is not None
        self._drain()
        self._mark = len(self.transcript)
        self.transcript.append(f"{time.monotonic() - self._t0:6.2f} >>> {command}\n")
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def _drain(self) -> None:
        while not self._lines.empty():
            self.transcript.append(self._lines.get())

    def expect(self, pattern: str, timeout: float) -> re.Match[str] | None:
        """The first line since the last command matching ``pattern``, waiting up to
        ``timeout`` s for it; None if it does not come."""
        deadline = time.monotonic() + timeout
        seen = self._mark
        while True:
            self._drain()
            for line in self.transcript[seen:]:
                if m := re.search(pattern, line):
                    return m
            seen = len(self.transcript)
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            try:
                self.transcript.append(self._lines.get(timeout=left))
            except queue.Empty:
                return None

    def retry(self, command: str, pattern: str, attempts: int, timeout: float) -> re.Match[str]:
        """Send ``command`` until ``pattern`` shows up, as an operator would."""
        for _ in range(attempts):
            self.send(command)
            if m := self.expect(pattern, timeout):
                return m
        pytest.fail(f"MAVProxy: {command!r} never gave {pattern!r}:\n{self.output()}")

    def output(self) -> str:
        """The end of the transcript, for failure messages."""
        self._drain()
        return "".join(self.transcript)[-4000:]

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.send("exit")
                self.proc.wait(5)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(5)


def test_mavproxy_sees_vehicle_fetches_params_and_takes_off(tmp_path: Path) -> None:
    """Headless MAVProxy sees the heartbeat, gets the parameters, sets GUIDED, arms, takes off."""
    pytest.importorskip("MAVProxy", reason="MAVProxy cannot be installed here")
    port = free_udp_port()
    sim, truth = _start_sim(tmp_path, port)
    console = None
    try:
        console = _MavproxyConsole(port, tmp_path / "home")
        assert console.expect(r"Detected vehicle 1:1", 20), console.output()
        assert console.expect(r"online system 1", 5), console.output()
        assert console.expect(r"Mode STABILIZE", 5), console.output()
        # MAVProxy fetches the parameters by itself: MAVLink FTP first, which the sim
        # refuses at once, then PARAM_REQUEST_LIST.
        count = console.expect(r"Received (\d+) parameters", 15)
        assert count, console.output()
        assert int(count.group(1)) == len(default_parameters(Autopilot.ARDUPILOT,
                                                             load_vehicle("firefly")))
        console.send("param show GUID_TIMEOUT")
        assert console.expect(r"GUID_TIMEOUT\s+3(\.0*)?\b", 5), console.output()
        # The vehicle refuses GUIDED until its position estimate is usable (like a real
        # Copter after boot), so repeat the request as an operator would.
        console.retry("mode GUIDED", r"Mode GUIDED", 10, 2)
        console.retry("arm throttle", r"(?<!DIS)ARMED", 5, 3)
        console.send(f"takeoff {TAKEOFF_ALTITUDE:g}")
        assert console.expect(r"NAV_TAKEOFF: ACCEPTED", 5), console.output()
        *_, z = _wait_truth(truth, lambda r: r[3] > 0.9 * TAKEOFF_ALTITUDE, 20)
        # MAVProxy's own view of the climb: the relative altitude it received.
        console.send("status GLOBAL_POSITION_INT")
        m = console.expect(r"relative_alt\s*:\s*(-?\d+)", 5)
        assert m and int(m.group(1)) > 0.5 * TAKEOFF_ALTITUDE * 1000, console.output()
    finally:
        if console is not None:
            console.close()
        sim_output = sim.stop()
    assert z > 0.9 * TAKEOFF_ALTITUDE, sim_output[-3000:]


# -------------------------------------------------------------------------------- MAVSDK


async def _until(updates, predicate=lambda item: True):
    """The first item of an async generator satisfying ``predicate``; the generator is then
    closed, which unsubscribes."""
    async with aclosing(updates):
        async for item in updates:
            if predicate(item):
                return item
    raise AssertionError("subscription ended")


async def _retry(request, error: type[Exception], attempts: int = 10) -> None:
    """Repeat a MAVSDK request the vehicle refuses for now (e.g. before its estimate is valid)."""
    for attempt in range(attempts):
        try:
            return await request()
        except error:
            if attempt == attempts - 1:
                raise
            await asyncio.sleep(0.5)


async def _first_autopilot(mavsdk, timeout: float):
    """The first connected system with an autopilot, polled from MAVSDK's system list.

    ``Mavsdk.first_autopilot`` missed a system discovered between ``add_any_connection`` and
    its own subscription once on a busy CI machine (the component was logged as added, the
    call still timed out), so the list is read directly until ``timeout`` s pass."""
    deadline = time.monotonic() + timeout
    seen: list[tuple[bool, bool]] = []
    while time.monotonic() < deadline:
        systems = await mavsdk.get_systems()
        seen = [(await s.has_autopilot(), await s.is_connected()) for s in systems]
        for system, (autopilot, connected) in zip(systems, seen, strict=True):
            if autopilot and connected:
                return system
        await asyncio.sleep(0.1)
    print(f"MAVSDK's systems at the time-out, (has_autopilot, is_connected): {seen}")
    return None


def _distance(a, b) -> float:
    return sum((p - q) ** 2 for p, q in zip(a, b, strict=True)) ** 0.5


def _off_target(row: tuple[float, float, float, float]) -> float:
    """Distance of a truth row (t, x, y, z ENU) from TARGET_NED, m."""
    _t, east, north, up = row
    return _distance((north, east, -up), TARGET_NED)


async def _fly_offboard(port: int, truth: Path) -> float:
    """Connect, read position, arm, start offboard at TARGET_NED; the largest truth distance
    from the target over the last second of a 2 s hold, m."""
    from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
    from mavsdk.asyncio.plugins.offboard import OffboardAsync, OffboardError, PositionNedYaw
    from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await _first_autopilot(mavsdk, timeout=30.0)
        assert system is not None, "MAVSDK found no autopilot"
        assert await system.autopilot_type() == Autopilot.PX4
        telemetry, action, offboard = (TelemetryAsync(system), ActionAsync(system),
                                       OffboardAsync(system))

        # Position telemetry appears once the vehicle's estimate is valid.
        position = await _until(telemetry.subscribe_position())
        assert position.latitude_deg == pytest.approx(47.397742, abs=1e-4)
        pv = await _until(telemetry.subscribe_position_velocity_ned())
        assert abs(pv.position.north_m) < 0.1 and abs(pv.position.east_m) < 0.1

        # PX4 wants the setpoint stream before the switch (the sim: > 2 Hz for > 1 s), and
        # MAVSDK's start() sends just one before asking, so stream as the PX4 docs advise.
        setpoint = PositionNedYaw(*TARGET_NED, 0.0)

        async def stream() -> None:
            while True:
                await offboard.set_position_ned(setpoint)
                await asyncio.sleep(0.05)

        streaming = asyncio.create_task(stream())
        try:
            await asyncio.sleep(1.5)
            await _retry(action.arm, ActionError)
            await _retry(offboard.start, OffboardError)
        finally:
            streaming.cancel()  # from now on MAVSDK streams the setpoint itself (20 Hz)

        await _until(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.OFFBOARD)
        await _until(telemetry.subscribe_armed(), bool)

        def near(pv) -> bool:
            p = pv.position
            return _distance((p.north_m, p.east_m, p.down_m), TARGET_NED) < REACHED

        await _until(telemetry.subscribe_position_velocity_ned(), near)
        # The truth agrees (ENU: x east, y north, z up), and the vehicle stays there.
        start = time.monotonic()
        await asyncio.to_thread(_wait_truth, truth, lambda r: _off_target(r) < REACHED, 5.0)
        await asyncio.sleep(max(0.0, 2.0 - (time.monotonic() - start)))
        rows = _truth_positions(truth)
        settled = [r for r in rows if r[0] > rows[-1][0] - 1.0]
        await offboard.stop()
        return max(_off_target(r) for r in settled)


def test_mavsdk_offboard_reaches_position_setpoint(tmp_path: Path) -> None:
    """MAVSDK connects to the PX4 sim, reads position, arms, and offboard reaches a setpoint."""
    pytest.importorskip("mavsdk.asyncio", reason="mavsdk (4.x) cannot be installed here")
    port = free_udp_port()
    # On the wall clock from the start, heartbeating as a booted PX4 does: a held lock-step
    # start sends only its frame until a peer speaks, and twice on CI MAVSDK saw the
    # autopilot's component but never reported it connected.
    sim, truth = _start_sim(tmp_path, port, "--autopilot", "px4", lockstep=False)
    try:
        hold_error = asyncio.run(asyncio.wait_for(_fly_offboard(port, truth), timeout=80.0))
    except (TimeoutError, AssertionError) as error:
        pytest.fail(f"MAVSDK offboard flight failed ({error}); sim log:\n{sim.output()[-3000:]}")
    finally:
        sim.stop()
    assert hold_error < REACHED
