"""The IMU over the link and the log download, on real ArduCopter (SITL).

Starts ``../shared/sitl/arducopter --model x`` (loopback TCP only) with ``copter.parm`` and
``vehicle/configs/sitl_quad.parm``, flies a gentle excitation of ``--duration`` s for
``sitl_quad`` with ``mavsysid stream`` (which asks for RAW_IMU at the rate the link
carries, writes it on the pose rows, sets LOG_BITMASK's IMU_FAST for the flight and, after
landing, downloads the vehicle's DataFlash log over MAVLink), stops SITL by its PID, and
prints:

- the RAW_IMU rate asked and achieved, and the IMU in pose.csv (|specific force| and gyro
  on the ground before take-off);
- the download: size, link seconds, rate, requests, and which of SITL's own files in its
  ``logs/`` directory the bytes are (equal to, or the start of: ArduPilot may write on
  after listing the log);
- the downloaded log read back (`mavsysid.formats.dataflash.read_dataflash`): its IMU
  message and rate, filter, position, motor outputs and ESC speeds.

    python bench/sitl_log_download.py [--duration 30] [--speedup 1] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.support.sitl import running_sitl  # noqa: E402
from tests.support.stream_flights import flight_dir, run_stream  # noqa: E402

SITL_PARMS = REPO / "vehicle" / "configs" / "sitl_quad.parm"
BOX = (-3.0, -3.0, 0.5, 3.0, 3.0, 3.0)


def _trajectory(path: Path, duration: float) -> Path:
    from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
    from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
    from mavsysid.vehicle.config import load_vehicle

    spec = ExcitationSpec(duration=duration, center=(0.0, 0.0, 1.5), amplitude=(0.8, 0.6, 0.3))
    write_trajectory_file(path, trajectory_file_for(excitation_trajectory(spec),
                                                    load_vehicle("sitl_quad"), box=BOX))
    return path


def _report(flight: Path, sitl_logs: Path, stream_seconds: float) -> None:
    from mavsysid.formats.dataflash import read_dataflash
    from mavsysid.formats.poselog import read_pose_log
    from mavsysid.vehicle.config import load_vehicle

    meta = json.loads((flight / "meta.json").read_text())
    imu = meta.get("imu", {})
    print(f"stream: {stream_seconds:.0f} s wall; IMU {imu.get('message')} asked "
          f"{imu.get('requested_hz')} Hz, {imu.get('preflight_hz', 0.0):.1f} Hz before the "
          f"flight, {meta.get('telemetry_rates_hz', {}).get('flight', {}).get('RAW_IMU')} Hz "
          f"over it; in pose.csv: {imu.get('in_pose_csv')}, row minus IMU time "
          f"{imu.get('lag_s')}")
    pose = read_pose_log(flight / "pose.csv", 4)
    if pose.accel is not None:
        ground = pose.position[:, 2] < 0.05
        print(f"pose.csv on the ground ({ground.sum()} rows): |f| "
              f"{np.linalg.norm(pose.accel[ground], axis=1).mean():.3f} m/s², mean gyro "
              f"{np.abs(pose.gyro[ground]).mean(axis=0).round(4)} rad/s")
    record = meta.get("autopilot_log")
    print(f"download: {record}")
    if not record or "file" not in record:
        return
    path = flight / record["file"]
    own = sorted(sitl_logs.glob("*.BIN")) if sitl_logs.is_dir() else []
    data = path.read_bytes()
    same = [p.name for p in own if p.read_bytes()[:len(data)] == data]
    print(f"SITL's own logs: {[p.name + f' {p.stat().st_size} B' for p in own]}; "
          f"the download is (the start of): {same}")
    log = read_dataflash(path, load_vehicle("sitl_quad"))
    for series in (log.gyro, log.accel):
        t = series.t
        print(f"  {series.label}: {t.size} samples, {(t.size - 1) / (t[-1] - t[0]):.1f} Hz "
              f"mean, median period {1e3 * np.median(np.diff(t)):.2f} ms")
    first = log.accel.t < log.accel.t[0] + 1.0
    print(f"  first second: |f| {np.linalg.norm(log.accel.values[first].mean(axis=0)):.3f} "
          f"m/s², gyro {log.gyro.values[:first.sum()].mean(axis=0).round(4)} rad/s")
    print(f"  filter {log.imu_filter}, position {log.imu_position}")
    outputs = log.motor_outputs
    shown = None if outputs is None else (outputs.kind, outputs.series.values.shape)
    print(f"  motor outputs {shown}, ESC speeds {[s.values.shape for s in log.esc_speeds]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--speedup", type=float, default=1.0)
    parser.add_argument("--keep", type=Path)
    args = parser.parse_args()
    work = args.keep or Path(tempfile.mkdtemp(prefix="sitl_log_"))
    work.mkdir(parents=True, exist_ok=True)
    trajectory = _trajectory(work / "excitation.json", args.duration)
    with running_sitl(work / "sitl", defaults=[SITL_PARMS], model="x",
                      speedup=args.speedup) as sitl:
        start = time.monotonic()
        done = run_stream(trajectory, "--connect", sitl.connect, "--vehicle", "sitl_quad",
                          "--box", ",".join(f"{b:g}" for b in BOX), "--set-limits",
                          "--speedup", f"{args.speedup:g}", "--prearm-timeout", "300",
                          "--log-dir", str(work / "logs"), cwd=work, timeout=1800,
                          lockstep=False)
        seconds = time.monotonic() - start
    (work / "stream.err").write_text(done.stderr)
    print(f"stream exit {done.returncode}: {done.stderr.strip().splitlines()[-1]}")
    _report(flight_dir(work / "logs"), work / "sitl" / "logs", seconds)
    print(f"kept in {work}")


if __name__ == "__main__":
    main()
