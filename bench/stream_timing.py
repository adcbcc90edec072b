"""Setpoint stream timing against `mavsysid sim` in real time (issue 5's bench).

Runs ``mavsysid sim`` as its own process (speedup 1) and streams a 60 s excitation
trajectory to it at 50 Hz over UDP loopback with the streamer of ``mavsysid stream``,
then prints:

- the achieved setpoint rate and the deviation of each setpoint period from nominal
  (mean, p99, max; the streamer's own send times, cross-checked with the gaps between the
  SET_POSITION_TARGET_LOCAL_NED records of flight.tlog), stalls, late and dropped
  setpoints, and the scheduling the streamer ran with (`mavsysid.flight.ground.realtime`);
- the end-to-end latency setpoint → telemetry reflecting it. There is no echo of the
  setpoint in the telemetry (the sim sends no POSITION_TARGET_LOCAL_NED), so it is
  measured on the vehicle's response: while hovering after the trajectory, with ESC and
  position telemetry raised to 250 Hz, the setpoint's vertical acceleration steps by
  ±1.5 m/s² and the latency is the time from sending that setpoint to receiving the
  first ESC_TELEMETRY_1_TO_4 whose rpm sum left the hover band (5 σ of the last 0.2 s,
  at least 30 rpm). Both stamps are the streamer's clock. It includes the uplink, the
  wait for the sim's next 2 ms control tick, the controller and the first 1 ms physics
  steps of the motors (τ = 25 ms: the first tick already moves the rpm sum by ~100), the
  wait for the telemetry slot (≤ 4 ms at 250 Hz) and the downlink.

    python bench/stream_timing.py [--duration 60] [--rate 50] [--steps 20] [--load 4]

``--load N`` starts N busy processes (``while :; do :; done``) for the whole run, to
measure the stream with other processes competing for the cores; they are stopped at
the end. A stall is a setpoint period more than 100 ms longer than nominal.

The period figures measure the computer as much as the streamer: with other processes
competing for the cores, wake-ups come late by milliseconds. On a shared machine run it
(streamer and sim alike) with a higher priority, e.g. ``nice -n -10 python bench/…``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from mavsysid.flight.ground.setpoints import Setpoint
from mavsysid.flight.ground.stream_session import StreamSession, StreamSettings
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.pipeline.stream import run_stream
from mavsysid.vehicle.config import load_vehicle

BOX = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)


class LatencySteps:
    """The at-end experiment: acceleration steps and the first ESC sample reacting."""

    def __init__(self, steps: int, accel: float = 1.5) -> None:
        self.steps, self.accel = steps, accel
        self.latencies: list[float] = []
        self.missed = 0
        self._esc: list[tuple[float, float]] = []

    def _on_message(self, msg, t: float) -> None:
        if msg.get_type() == "ESC_TELEMETRY_1_TO_4":
            self._esc.append((t, float(sum(msg.rpm))))

    def __call__(self, session: StreamSession) -> None:
        link, stream, commands = session.link, session.stream, session.commands
        for name in ("ESC_TELEMETRY_1_TO_4", "LOCAL_POSITION_NED"):
            commands.set_message_interval(name, 250.0)
        hover = stream.last
        assert hover is not None
        link.add_listener(self._on_message)
        try:
            for i in range(self.steps):
                link.poll(0.6)
                now = link.clock.now()
                band = np.array([s for t, s in self._esc if t > now - 0.2])
                mean, sigma = float(band.mean()), float(band.std())
                sign = 1.0 if i % 2 == 0 else -1.0
                step = Setpoint(hover.position, acceleration=(0.0, 0.0, sign * self.accel),
                                yaw=hover.yaw)
                schedule = stream.start(lambda _t, s=step: s)
                link.poll(0.1)
                sent = schedule.send_times[0]
                stream.start(lambda _t: hover)
                late = [t for t, s in self._esc
                        if t > sent and abs(s - mean) > max(5.0 * sigma, 30.0)]
                if late:
                    self.latencies.append(late[0] - sent)
                else:
                    self.missed += 1
        finally:
            link.remove_listener(self._on_message)
            for name in ("ESC_TELEMETRY_1_TO_4", "LOCAL_POSITION_NED"):
                commands.set_message_interval(name, session.settings.telemetry_rate)


def _tlog_periods(path: Path, t0: float, t1: float) -> np.ndarray:
    """Gaps between our SET_POSITION_TARGET_LOCAL_NED records with stamps in [t0, t1] s."""
    log = load_mavutil().mavlink_connection(str(path))
    stamps = []
    while (m := log.recv_match(type="SET_POSITION_TARGET_LOCAL_NED")) is not None:
        stamps.append(m._timestamp)
    log.close()
    s = np.array(stamps)
    return np.diff(s[(s >= t0) & (s <= t1)])


def _busy(count: int) -> list[subprocess.Popen]:
    """``count`` busy-loop processes competing for the cores (the caller stops them)."""
    return [subprocess.Popen(["sh", "-c", "while :; do :; done"]) for _ in range(count)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0, help="trajectory, s")
    parser.add_argument("--rate", type=float, default=50.0, help="setpoints, Hz")
    parser.add_argument("--steps", type=int, default=20, help="latency steps")
    parser.add_argument("--load", type=int, default=0, help="busy processes competing")
    args = parser.parse_args()
    busy = _busy(args.load)
    try:
        _run(args)
    finally:
        for process in busy:
            process.kill()
            process.wait()


def _run(args: argparse.Namespace) -> None:
    config = load_vehicle("firefly")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        traj = tmp / "excitation.json"
        write_trajectory_file(traj, trajectory_file_for(
            excitation_trajectory(ExcitationSpec(duration=args.duration)), config, box=BOX))
        port = free_udp_port()
        sim = subprocess.Popen(
            [sys.executable, "-m", "mavsysid", "sim", "--connect", f"udpout:127.0.0.1:{port}",
             "--vehicle", "firefly"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
        experiment = LatencySteps(args.steps)
        try:
            outcome = run_stream(traj, StreamSettings(connect=f"udp:127.0.0.1:{port}",
                                                      rate=args.rate, log_dir=tmp / "logs",
                                                      max_tracking_error=3.0,
                                                      heartbeat_timeout=180.0),
                                 say=lambda text: print(f"  {text}", file=sys.stderr),
                                 progress=False, at_end=experiment)
        finally:
            sim.terminate()
            sim.wait(timeout=10)
        meta = outcome.meta
        sp = meta["setpoints"]
        # The trajectory's setpoints: the window between its first and last, stamped in
        # the tlog with the same clock as the schedule (epoch + streamer time).
        window = meta["trajectory_window"]
        epoch = meta["tlog_epoch_unix_s"]
        # Strictly inside the window: its first gap would span the switch of schedules.
        gaps = _tlog_periods(outcome.directory / "flight.tlog",
                             epoch + window["streamer_start"] + 1e-3,
                             epoch + window["streamer_end"])
        nominal = 1.0 / args.rate
        dev = np.abs(gaps - nominal)
        print(f"stream  {args.duration:g} s trajectory at {args.rate:g} Hz, real time, "
              f"{args.load} busy processes (vehicle time {window['start']:.1f}–"
              f"{window['end']:.1f} s)")
        print(f"  achieved rate         {sp['rate_hz']:.3f} Hz ({sp['sent']} sent)")
        print(f"  period deviation      mean {1e3 * sp['period_deviation_mean_s']:.3f} ms, "
              f"p99 {1e3 * sp['period_deviation_p99_s']:.3f} ms, max "
              f"{1e3 * sp['period_deviation_max_s']:.3f} ms (streamer send times)")
        print(f"  tlog cross-check      p99 {1e3 * np.percentile(dev, 99):.3f} ms over "
              f"{dev.size} gaps (tlog record stamps)")
        print(f"  stalls (> 100 ms)     {int(np.sum(gaps - nominal > 0.1))} (tlog), max gap "
              f"{1e3 * float(gaps.max()):.1f} ms")
        print(f"  late (> 10 % period)  {sp['late']}")
        print(f"  scheduling            {meta['stream'].get('scheduling', '?')}")
        print(f"  dropped               {sp['dropped']}")
        tracking = meta.get("tracking", {})
        if tracking.get("rows"):
            print(f"  tracking              RMS {1e3 * tracking['rms_m']:.1f} mm, max "
                  f"{1e3 * tracking['max_m']:.1f} mm")
        lat = experiment.latencies
        if lat:
            print(f"latency setpoint → ESC telemetry reacting ({len(lat)} steps, "
                  f"{experiment.missed} missed): median {1e3 * statistics.median(lat):.1f} "
                  f"ms, p90 {1e3 * float(np.percentile(lat, 90)):.1f} ms, min "
                  f"{1e3 * min(lat):.1f} ms, max {1e3 * max(lat):.1f} ms")
        else:
            print(f"latency: no step detected ({experiment.missed} missed)")


if __name__ == "__main__":
    main()
