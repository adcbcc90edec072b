"""ArduCopter SITL against its reference θ (vehicle/configs/sitl_quad.toml): hover and yaw.

Starts ``../shared/sitl/arducopter --model x`` on loopback (instance 5 or higher) with
``copter.parm``, ``vehicle/configs/sitl_quad.parm`` and ``bench/sitl_reference.parm`` (the
motor command at 100 Hz, attitude and IMU at 400 Hz in the log), takes off in GUIDED with
pymavlink, hovers, turns in yaw steps (MAV_CMD_CONDITION_YAW), lands and stops SITL by its
PID. Then it reads the flight's own DataFlash log (``logs/*.BIN``) and the MAVLink motor
messages received in the hover, and reports:

- what the log records and how often (ESC, RCOU, ATT, POS, XKF1, IMU, SIM, …);
- the hover balance: Σ c_T n_i² against m g and against m |f| (f the mean IMU specific
  force), n_i through the config's motor curve from RCOU (10 Hz) and from the command the
  ESC stand-in rpm carries (100 Hz); and what the ESC rpm gives when read as a rotor speed;
- the yaw torque balance: j_z ṙ (ṙ from the 400 Hz IMU gyro) against SITL's own yaw law
  (docs/vehicles/sitl_quad.md) and the c_M and c_D a least-squares fit of the paper's yaw
  law −c_M Σ ε_i n_i² − c_D Σ c_T n_i² |r_i|² r gives on this manoeuvre.

    python bench/sitl_reference.py [--hover 20] [--speedup 4] [--as-shipped] [--keep DIR]

``--as-shipped`` leaves out ``bench/sitl_reference.parm``: SITL as ``sitl_quad.parm`` sets
it up, with no ESC telemetry and ArduCopter's default logging (hover balance from RCOU only,
no yaw balance). SITL is lock-stepped to its own physics, so ``--speedup`` changes the wall
time, not the figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import butter, filtfilt

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from mavsysid.flight.mavlink_setup import load_mavutil  # noqa: E402
from mavsysid.formats.motor_curve import (  # noqa: E402
    rotor_speed_from_pwm,
    rotor_speed_from_throttle,
)
from mavsysid.vehicle.config import VehicleConfig, load_vehicle  # noqa: E402
from mavsysid.vehicle.mav_model import collective_thrust, rotor_thrust  # noqa: E402

#: The shared SITL build beside the checkout (``../shared/sitl``; a worktree one level deeper).
SITL_DIR = next((d for d in (REPO.parent / "shared" / "sitl", REPO.parents[1] / "shared" / "sitl")
                 if d.is_dir()), REPO.parent / "shared" / "sitl")
VEHICLE = REPO / "vehicle" / "configs" / "sitl_quad.toml"
VEHICLE_PARMS = REPO / "vehicle" / "configs" / "sitl_quad.parm"
BENCH_PARMS = REPO / "bench" / "sitl_reference.parm"
#: Home of ../shared/sitl/README.md: lat, lon, altitude AMSL (m), heading.
HOME = (47.397, 8.545, 488.0, 0.0)
#: Where the config's c_T holds: 490 m AMSL (its comments).
REFERENCE_ALTITUDE = 490.0
#: SITL's gravity (GRAVITY_MSS, libraries/AP_Math/definitions.h:44), m/s².
SITL_GRAVITY = 9.80665
#: ESC rpm at full command: SIM_VIB_MOT_MAX (Hz) × 60 (bench/sitl_reference.parm).
ESC_FULL_RPM = 100.0 * 60.0
#: SITL's reaction torque per rotor, 0.05 · diagonal_size · c · T (SIM_Motor.cpp:71-72,
#: diagonal_size 0.35 m SIM_Frame.h:88), as the lever 0.05 · 0.35 m.
YAW_LEVER = 0.05 * 0.35
#: SITL's rotational damping ω̇ −= ω · radians(400) / refRotRate (SIM_Frame.cpp:665-670), 1/s.
ROTATION_DAMPING = math.radians(400.0) / 120.0
#: Momentum drag per rotor over sqrt(ρ T): mdrag_coef · sqrt(disc_area / 4)
#: (SIM_Motor.cpp:111-114, SIM_Frame.h:131-134, SIM_Frame.cpp:585), m.
MOMENTUM_DRAG = 0.2 * math.sqrt(0.385 / 4.0)
#: DataFlash messages whose rates are reported; per instance/core where they have one.
RATE_TYPES = ("ESC", "RCOU", "ATT", "RATE", "POS", "XKF1", "IMU", "SIM", "SIM2", "BAT",
              "CTUN", "MOTB", "GPS", "BARO", "VISP")
_INSTANCE_FIELD = {"ESC": "Instance", "IMU": "I", "XKF1": "C", "GPS": "I", "BARO": "I"}
#: MAVLink motor messages asked for at this rate during the flight, Hz.
MAVLINK_MOTOR_RATE = 50.0
#: Instances tried (5 and up: lower ones are for the test suite's peers).
INSTANCES = range(5, 40)
#: Low-pass (Hz) applied alike to both sides of the yaw balance before comparing.
YAW_FILTER_HZ = 4.0


def air_density(alt_amsl: float) -> float:
    """ArduPilot's 1976 atmosphere below 11 km (AP_Baro_atmosphere.cpp:211-230), kg/m³."""
    radius, r_specific, lapse = 6356.766e3, 287.053072, -6.5e-3
    h = radius * alt_amsl / (radius + alt_amsl)  # geopotential height
    temp = 320.650 + lapse * (h + 5000.0)
    return 1.930467 * (temp / 320.650) ** (-(SITL_GRAVITY / (lapse * r_specific) + 1.0))


# ---------------------------------------------------------------------------------------
# The flight


def _bindable(*ports: int) -> bool:
    """Whether all ``ports`` of 127.0.0.1 can be bound together right now (only a listener
    blocks a port with SO_REUSEADDR, and a check never connects: SITL serves one client)."""
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_STREAM) for _ in ports]
    try:
        for s, port in zip(sockets, ports, strict=True):
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(("127.0.0.1", port))
        return True
    except OSError:
        return False
    finally:
        for s in sockets:
            s.close()


@contextmanager
def sitl(directory: Path, parms: list[Path], speedup: float) -> Iterator[int]:
    """Run SITL in ``directory`` for the ``with`` block; yields its SERIAL0 TCP port."""
    binary = SITL_DIR / "arducopter"
    if not os.access(binary, os.X_OK):
        raise SystemExit(f"no executable ArduCopter SITL at {binary}")
    instance = next((n for n in INSTANCES if _bindable(5760 + 10 * n, 5762 + 10 * n)), None)
    if instance is None:
        raise SystemExit("no free SITL instance on 127.0.0.1")
    port = 5760 + 10 * instance
    defaults = ",".join(str(p.resolve()) for p in [SITL_DIR / "copter.parm", *parms])
    directory.mkdir(parents=True, exist_ok=True)
    with open(directory / "sitl.out", "wb") as out:
        process = subprocess.Popen(
            [str(binary.resolve()), "-w", "--model", "x", "--speedup", f"{speedup:g}",
             "--defaults", defaults, f"-I{instance}", "--home", ",".join(map(str, HOME)),
             "--sim-address=127.0.0.1"],
            cwd=directory, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30.0
        while _bindable(port):
            if process.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"SITL did not listen on 127.0.0.1:{port}: see "
                                 f"{directory / 'sitl.out'}")
            time.sleep(0.1)
        yield port
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=10)


@dataclass
class Flight:
    """Phase boundaries (autopilot ms since boot) and the MAVLink motor messages of the hover."""

    hover: tuple[int, int] = (0, 0)
    yaw: tuple[int, int] = (0, 0)
    servo: list[tuple[int, list[float]]] = field(default_factory=list)
    esc: list[list[float]] = field(default_factory=list)


class Pilot:
    """A minimal ground station: GUIDED take-off, hover, yaw steps, LAND."""

    def __init__(self, port: int) -> None:
        mavutil = load_mavutil()
        self.conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                               source_component=190, retries=30)
        if self.conn.wait_heartbeat(timeout=60) is None:
            raise SystemExit("no heartbeat from SITL")
        self.boot_ms = 0
        self.z = 0.0
        self.armed = False
        self.last_beat = 0.0
        self.record: Flight | None = None
        wanted = {"ATTITUDE": 20.0, "LOCAL_POSITION_NED": 20.0,
                  "SERVO_OUTPUT_RAW": MAVLINK_MOTOR_RATE,
                  "ESC_TELEMETRY_1_TO_4": MAVLINK_MOTOR_RATE}
        for name, hz in wanted.items():
            self.command(511, getattr(mavutil.mavlink, f"MAVLINK_MSG_ID_{name}"), 1e6 / hz)

    def command(self, cmd: int, *params: float) -> None:
        p = [*params, 0, 0, 0, 0, 0, 0, 0][:7]
        self.conn.mav.command_long_send(1, 1, cmd, 0, *p)

    def pump(self, seconds: float) -> None:
        """Read messages for ``seconds`` wall s, sending a GCS heartbeat every second."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if time.monotonic() - self.last_beat > 1.0:
                self.conn.mav.heartbeat_send(6, 8, 0, 0, 0)  # GCS, no autopilot
                self.last_beat = time.monotonic()
            m = self.conn.recv_match(blocking=True, timeout=0.1)
            if m is None:
                continue
            kind = m.get_type()
            if hasattr(m, "time_boot_ms"):
                self.boot_ms = max(self.boot_ms, int(m.time_boot_ms))
            if kind == "LOCAL_POSITION_NED":
                self.z = float(m.z)
            elif kind == "HEARTBEAT" and m.get_srcComponent() == 1:
                self.armed = bool(m.base_mode & 128)
            elif kind == "STATUSTEXT" and os.environ.get("SITL_REFERENCE_VERBOSE"):
                print("  SITL:", m.text)
            elif self.record is not None and kind == "SERVO_OUTPUT_RAW":
                pwm = [float(getattr(m, f"servo{i}_raw")) for i in (1, 2, 3, 4)]
                self.record.servo.append((int(m.time_usec), pwm))
            elif self.record is not None and kind == "ESC_TELEMETRY_1_TO_4":
                self.record.esc.append([float(v) for v in m.rpm])

    def wait_sim(self, seconds: float, timeout: float = 600.0) -> None:
        """Pump until the autopilot's clock advanced by ``seconds``."""
        start, end = self.boot_ms, time.monotonic() + timeout
        while self.boot_ms - start < 1000.0 * seconds:
            if time.monotonic() > end:
                raise SystemExit("SITL's clock stopped")
            self.pump(0.1)

    def take_off(self, altitude: float, timeout: float = 300.0) -> None:
        """GUIDED, arm once the pre-arm checks pass, take off and climb to ``altitude``."""
        end = time.monotonic() + timeout
        while not self.armed:
            if time.monotonic() > end:
                raise SystemExit("SITL never armed (pre-arm checks)")
            self.command(176, 1, 4)  # DO_SET_MODE GUIDED
            self.command(400, 1)  # arm
            self.pump(2.0)
        self.command(22, 0, 0, 0, 0, 0, 0, altitude)  # NAV_TAKEOFF
        while -self.z < altitude - 0.1:
            if time.monotonic() > end:
                raise SystemExit("take-off did not reach its altitude")
            self.pump(0.2)

    def yaw_steps(self, steps: int, angle: float, rate: float, dwell: float) -> None:
        """Alternate relative yaw turns of ``angle`` deg at ``rate`` deg/s, ``dwell`` s each."""
        for i in range(steps):
            self.command(115, angle, rate, 1 if i % 2 == 0 else -1, 1)  # CONDITION_YAW
            self.wait_sim(dwell)

    def land(self, timeout: float = 300.0) -> None:
        self.command(176, 1, 9)  # DO_SET_MODE LAND
        end = time.monotonic() + timeout
        while self.armed and time.monotonic() < end:
            self.pump(0.5)


def fly(directory: Path, parms: list[Path], hover: float, speedup: float) -> Flight:
    """Boot SITL, take off to 2 m, hover ``hover`` s, turn in yaw, land."""
    flight = Flight()
    with sitl(directory, parms, speedup) as port:
        pilot = Pilot(port)
        try:
            pilot.take_off(REFERENCE_ALTITUDE - HOME[2])
            pilot.wait_sim(5.0)  # settle after the climb
            start, pilot.record = pilot.boot_ms, flight
            pilot.wait_sim(hover)
            flight.hover, pilot.record = (start, pilot.boot_ms), None
            start = pilot.boot_ms
            pilot.yaw_steps(6, 90.0, 90.0, 3.0)
            flight.yaw = (start, pilot.boot_ms)
            pilot.land()
        finally:
            pilot.conn.close()
    return flight


# ---------------------------------------------------------------------------------------
# The log


def read_bin(path: Path) -> dict[str, list[Any]]:
    """Every message of a DataFlash log, by type."""
    load_mavutil()
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(path))
    found: dict[str, list[Any]] = defaultdict(list)
    while (m := log.recv_msg()) is not None:
        found[m.get_type()].append(m)
    log.close()
    return found


def columns(rows: list[Any], *names: str) -> np.ndarray:
    """Fields of ``rows`` as floats, shape (len(rows), len(names))."""
    return np.array([[float(getattr(r, n)) for n in names] for r in rows], dtype=float)


def seconds(rows: list[Any]) -> np.ndarray:
    return np.array([r.TimeUS for r in rows], dtype=float) * 1e-6


def instance(found: dict[str, list[Any]], kind: str, which: int = 0) -> list[Any]:
    """The rows of one instance (IMU, ESC, EKF core …) of a message type, else all rows."""
    rows = found.get(kind, [])
    key = _INSTANCE_FIELD.get(kind)
    if not rows or key is None or not hasattr(rows[0], key):
        return rows
    return [r for r in rows if int(getattr(r, key)) == which]


def within(t: np.ndarray, span_ms: tuple[int, int]) -> np.ndarray:
    return (t >= span_ms[0] * 1e-3) & (t <= span_ms[1] * 1e-3)


def esc_commands(found: dict[str, list[Any]], t: np.ndarray) -> np.ndarray | None:
    """The motor commands c_1..c_4 the stand-in ESC rpm carries, at times ``t``; None without.

    Each ESC instance is interpolated on its own time stamps: a log that dropped messages
    (DataFlash ``DSF.Dp``) has them at different times.
    """
    rows = [instance(found, "ESC", i) for i in range(4)]
    if not all(rows):
        return None
    return np.column_stack([np.interp(t, seconds(r), columns(r, "RPM")[:, 0]) / ESC_FULL_RPM
                            for r in rows])


def print_rates(found: dict[str, list[Any]], span_ms: tuple[int, int]) -> None:
    print("DataFlash messages while flying (Hz; ESC and IMU per instance, XKF1 per core):")
    parts = []
    for kind in RATE_TYPES:
        rows = instance(found, kind)
        t = seconds(rows) if rows else np.zeros(0)
        count = int(within(t, span_ms).sum())
        if count:
            parts.append(f"{kind} {count / ((span_ms[1] - span_ms[0]) * 1e-3):.1f}")
    print("  " + ", ".join(parts))


def hover_balance(found: dict[str, list[Any]], flight: Flight, vehicle: VehicleConfig) -> None:
    """Σ c_T n² against m g and m |f| in the hover, from each record of the motor command."""
    c_T = vehicle.parameters.c_T
    pos = [r for r in found.get("POS", []) if within(seconds([r]), flight.hover)[0]]
    alt = float(np.mean(columns(pos, "Alt"))) if pos else REFERENCE_ALTITUDE
    rho = air_density(alt) / air_density(REFERENCE_ALTITUDE)
    weight = vehicle.mass * SITL_GRAVITY
    imu = instance(found, "IMU")
    sel = within(seconds(imu), flight.hover)
    specific = float(np.linalg.norm(np.mean(columns(imu, "AccX", "AccY", "AccZ")[sel], axis=0)))
    print(f"\nHover, {(flight.hover[1] - flight.hover[0]) * 1e-3:.1f} s at {alt:.2f} m AMSL "
          f"(c_T there = {rho:.5f} × the config's); m g = {weight:.3f} N, m |f| = "
          f"{vehicle.mass * specific:.3f} N (IMU, {sel.sum()} samples)")

    def line(label: str, n: np.ndarray) -> None:
        thrust = collective_thrust(c_T * rho, n)
        print(f"  {label:34s} n = {np.array2string(np.mean(n, axis=0), precision=1)} rad/s; "
              f"Σ c_T n² = {np.mean(thrust):.3f} N (sd {np.std(thrust):.3f}): "
              f"/ m g = {np.mean(thrust) / weight:.4f}, / m |f| = "
              f"{np.mean(thrust) / (vehicle.mass * specific):.4f}")

    rcou = found["RCOU"]
    sel = within(seconds(rcou), flight.hover)
    pwm = columns(rcou, "C1", "C2", "C3", "C4")[sel]
    print(f"  RCOU mean PWM {np.array2string(np.mean(pwm, axis=0), precision=1)} µs")
    line(f"RCOU ({sel.sum()} samples), curve:", rotor_speed_from_pwm(pwm, vehicle))
    if flight.servo:
        servo = np.array([s for _, s in flight.servo])
        line(f"SERVO_OUTPUT_RAW ({len(servo)}), curve:", rotor_speed_from_pwm(servo, vehicle))
    grid = np.arange(flight.hover[0], flight.hover[1], 10) * 1e-3  # the ESC's 100 Hz
    c = esc_commands(found, grid)
    if c is not None:
        n_curve = rotor_speed_from_throttle(c, vehicle.limits.rotor_speed_max,
                                            vehicle.motor.thrust_expo)
        line(f"ESC c = rpm/{ESC_FULL_RPM:g} ({len(grid)}), curve:", n_curve)
        line("ESC rpm read as the rotor speed:", c * vehicle.limits.rotor_speed_max)
    if flight.esc:
        rpm = np.array(flight.esc)
        line(f"ESC_TELEMETRY rpm ({len(rpm)}) as speed:", rpm * 2.0 * math.pi / 60.0)


def _lowpass(x: np.ndarray, rate: float) -> np.ndarray:
    b, a = butter(2, YAW_FILTER_HZ / (0.5 * rate))
    return filtfilt(b, a, x, axis=0)


def yaw_balance(found: dict[str, list[Any]], flight: Flight, vehicle: VehicleConfig) -> None:
    """j_z ṙ against SITL's yaw law and a least-squares fit of the paper's, in the yaw steps.

    Everything is interpolated onto a uniform 400 Hz grid from its own time stamps (the log
    may have dropped messages), low-passed alike, and the gyro's delay behind the motor
    commands (the autopilot logs its filtered gyro) is found by correlation first.
    """
    imu = instance(found, "IMU")
    t_imu = seconds(imu)
    sel = within(t_imu, flight.yaw)
    span = (flight.yaw[1] - flight.yaw[0]) * 1e-3
    print(f"\nYaw steps, {span:.1f} s, IMU logged at {sel.sum() / span:.0f} Hz:")
    t = np.arange(flight.yaw[0], flight.yaw[1], 2.5) * 1e-3
    c = esc_commands(found, t)
    if c is None or sel.sum() / span < 100.0:
        print("  needs the ESC command record and the 400 Hz IMU (bench/sitl_reference.parm)")
        return
    p = vehicle.parameters
    r = -np.interp(t, t_imu, columns(imu, "GyrZ")[:, 0])  # body FRD z down → FLU z up
    n = rotor_speed_from_throttle(c, vehicle.limits.rotor_speed_max, vehicle.motor.thrust_expo)
    pos = [row for row in found.get("POS", []) if within(seconds([row]), flight.yaw)[0]]
    rho = air_density(float(np.mean(columns(pos, "Alt")))) if pos else air_density(490.0)
    thrust = rotor_thrust(p.c_T * rho / air_density(REFERENCE_ALTITUDE), n)
    eps = vehicle.rotor_directions
    arm2 = np.sum(vehicle.rotor_positions[:, :2] ** 2, axis=1)
    j_z, rate = p.J[2], 400.0
    # SITL's law (docs/vehicles/sitl_quad.md, "Yaw"): reaction torque, momentum drag of the
    # hubs moving at ω × r_i, and the rotational damping.
    sitl_torque = (-(eps * YAW_LEVER * c * thrust).sum(axis=1)
                   - MOMENTUM_DRAG * math.sqrt(rho) * (np.sqrt(thrust) * arm2).sum(axis=1) * r
                   - j_z * ROTATION_DAMPING * r)
    # The paper's: −c_M Σ ε n² and the c_D rotor drag of the hubs (ω × r_i)_xy.
    basis = np.column_stack([-(eps * n**2).sum(axis=1), -(thrust * arm2).sum(axis=1) * r])
    y = _lowpass(j_z * np.gradient(r, t), rate)
    sitl_f, basis_f = _lowpass(sitl_torque, rate), _lowpass(basis, rate)
    lags = np.arange(0, 41)  # 0–100 ms
    score = [np.corrcoef(sitl_f[100 - k:-100 - k], y[100:-100])[0, 1] for k in lags]
    lag = int(lags[int(np.argmax(score))])
    y = y[100:-100]
    sitl_f, basis_f = sitl_f[100 - lag:-100 - lag], basis_f[100 - lag:-100 - lag]
    resid = y - sitl_f
    print(f"  |j_z ṙ| up to {np.max(np.abs(y)):.3f} N·m, |r| up to {np.max(np.abs(r)):.2f} rad/s;"
          f" logged gyro {1e3 * lag / rate:.1f} ms behind the motor commands")
    print(f"  SITL's yaw law: RMS residual {np.sqrt(np.mean(resid**2)):.4f} N·m of RMS "
          f"{np.sqrt(np.mean(y**2)):.4f} N·m (R² {1 - np.var(resid) / np.var(y):.4f})")
    coef, *_ = np.linalg.lstsq(basis_f, y, rcond=None)
    resid = y - basis_f @ coef
    print(f"  paper's yaw law, fitted: c_M = {coef[0]:.4e} (reference {p.c_M:.4e}, "
          f"{coef[0] / p.c_M - 1:+.1%}), c_D = {coef[1]:.4f} s/m (reference {p.c_D:.4f}, "
          f"{coef[1] / p.c_D - 1:+.1%}); R² {1 - np.var(resid) / np.var(y):.4f}")
    fixed = y - basis_f[:, 1] * p.c_D
    c_m_only = float(basis_f[:, 0] @ fixed / (basis_f[:, 0] @ basis_f[:, 0]))
    print(f"  with c_D at its reference: c_M = {c_m_only:.4e} ({c_m_only / p.c_M - 1:+.1%})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hover", type=float, default=20.0, help="hover time, s (sim)")
    parser.add_argument("--speedup", type=float, default=1.0, help="SITL --speedup")
    parser.add_argument("--as-shipped", action="store_true",
                        help="only sitl_quad.parm: no ESC telemetry, default logging")
    parser.add_argument("--keep", type=Path, help="run SITL in this directory and keep it")
    parser.add_argument("--log", type=Path, help="report on a kept run's directory, no flight")
    args = parser.parse_args(argv)
    vehicle = load_vehicle(str(VEHICLE))
    with tempfile.TemporaryDirectory(prefix="sitl_reference_") as tmp:
        directory = args.log or args.keep or Path(tmp)
        if args.log:
            flight = Flight(**json.loads((directory / "flight.json").read_text()))
        else:
            parms = [VEHICLE_PARMS, *([] if args.as_shipped else [BENCH_PARMS])]
            print(f"SITL {SITL_DIR / 'arducopter'} --model x, defaults copter.parm, "
                  f"{', '.join(p.name for p in parms)}; speedup {args.speedup:g}")
            flight = fly(directory, parms, args.hover, args.speedup)
            (directory / "flight.json").write_text(json.dumps(dataclasses.asdict(flight)))
        logs = sorted((directory / "logs").glob("*.BIN"))
        if not logs:
            raise SystemExit(f"no DataFlash log in {directory / 'logs'}")
        found = read_bin(logs[-1])
    dropped = found["DSF"][-1].Dp if found.get("DSF") else 0
    print(f"log {logs[-1].name}: {sum(map(len, found.values()))} messages, "
          f"{dropped} dropped by the logger (DSF.Dp)")
    print_rates(found, (flight.hover[0], flight.yaw[1]))
    hover_balance(found, flight, vehicle)
    yaw_balance(found, flight, vehicle)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
