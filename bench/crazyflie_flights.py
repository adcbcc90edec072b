"""Real Crazyflie flights, converted on the fly: what `estimate` says and what the balance says.

IMRCLab's ``crazyflie-data-collection`` has no licence, so nothing of it enters this
repository: this bench reads a checkout given on the command line, imports the
checkout's own uSD-log decoder (``scripts/cfusdlog.py``) at run time, and converts each
flight into a temporary directory:

* ``pose.csv`` (docs/architecture.md, "Pose log"): every row of the 500 Hz
  ``fixedFrequency`` event, t = timestamp (ms → s), position ``stateEstimate.x/y/z``
  (the on-board estimator fused with motion capture; world z up), quaternion
  ``stateEstimate.qw..qz`` (body → world, verified against the gyroscope), rotor speeds
  ``rpm.m1..m4`` (rpm → rad/s) in the vehicle file's rotor order M1..M4, and the on-board
  IMU (`imu_columns`): ``gyro.x/y/z`` (deg/s → rad/s) as ``gyro_x..z`` and ``acc.x/y/z``
  (g → m/s²) as ``acc_x..z``. The Crazyflie's body frame is FLU (x forward, y left, z
  up), checked on the flights: the gyro correlates with the rates of the logged attitude
  at 0.99 (roll, pitch) with a positive slope, and the accelerometer reads +1 g on z at
  rest, its specific force rotated into the world less gravity following the pose's
  acceleration (correlation 0.97–0.99 horizontally). ``--no-imu`` writes the same rows
  without the IMU columns. Rows are written as logged, repeated poses and dead rotor
  channels included: that is the tool's input;
* a vehicle TOML: mass from the flights' READMEs (34.7 g brushed, 37 g brushless), the X
  layout checked on the flights (arm 0.046 m; M1 front right CCW, M2 back right CW, M3 back left
  CCW, M4 front left CW), ``rotor_speed_max`` the highest speed of the thrust stand, and
  a **generic prior θ**, what a user who knows mass, arm and top rotor speed would write:
  c_T for a thrust-to-weight ratio of 2 at top speed (2 m g = 4 c_T n_max²), c_M a 1 cm
  torque-to-thrust ratio, c_D = 0.01 s/m, and J of a uniform box spanning the motors
  (side 2 × arm, 2 cm high). It is 30–70 % off the references, in both directions.
  ``--prior thirty`` instead puts θ 30 % off the references in the directions of issue 33
  (`PRIOR_FACTORS`: c_T and c_M × 1.3, c_D and J × 0.7); c_M and c_D have no stand
  reference, so their factor multiplies the generic prior's value.

References: c_T by least squares of the stand's total thrust on Σ n² (brushed: both files
of ``system-id/data/cf21_bitcraze2021``, F = weight · g; brushless: the scale readings of
``manual_data_calib_brushless.csv`` against motor 4's median speed at each PWM step of
``data_calib_brushless.csv``, the motor the repository's own fit uses, F/4 per rotor);
j_x, j_y, j_z of Förster (2015, Crazyflie 2.0, bifilar pendulum), a weaker reference for
the brushless airframe; c_M and c_D are not measured.

Each flight runs ``mavsysid estimate`` as a user runs it (a subprocess writing
``estimate.json``), and on request (``--library``) the force and torque balance alone
(`fit_wrench_balance`). Printed per flight: duration, per parameter the error against the
reference, σ, status (D = determined), whether the 95 % interval covers the reference,
the held-out RMSE ratio, run times. An empty flight file is given to ``estimate`` as an
empty pose log, to show its one-line refusal.

    nice python bench/crazyflie_flights.py --repo /path/to/crazyflie-data-collection \\
        [--json out.json] [--markdown table.md] [--flights jana0,eckart1] [--jobs 2]
        [--library] [--diagnose] [--prior generic|thirty] [--no-imu]

With ``--diagnose``, each flight also runs ``mavsysid diagnose --estimate estimate.json``
(time, named effects, held-out ratios before → after).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.estimation.balance.fit import fit_wrench_balance
from mavsysid.estimation.balance.theta import widened_sigma
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import Z95
from mavsysid.formats.poselog import PoseLogWriter, read_pose_log
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle, vehicle_to_toml
from mavsysid.vehicle.config_types import RotorConfig
from mavsysid.vehicle.constants import GRAVITY, RPM_TO_RAD_S

from bench.crazyflie_report import markdown_table, print_summary, print_table
from mavsysid.cli.main import exit_code
from mavsysid.errors import LogFormatError, MavsysidError

#: Per vehicle: data folder, file prefix, mass (kg).
VEHICLES = {"brushed": ("brushed_flights/data", "jana", 0.0347),
            "brushless": ("brushless_flights/data", "eckart", 0.037)}
#: Förster (2015) inertia, kg·m².
FOERSTER_J = (16.571710e-6, 16.655602e-6, 29.261652e-6)
ARM = 0.046
#: M1..M4: (x, y) signs and spin direction (+1 counter-clockwise seen from above).
LAYOUT = (((1, -1), 1), ((-1, -1), -1), ((-1, 1), 1), ((1, 1), -1))
#: ``--prior thirty``: θ's factor on the reference (c_T, c_D, c_M, j_x, j_y, j_z).
PRIOR_FACTORS = np.array([1.3, 0.7, 1.3, 0.7, 0.7, 0.7])
#: The uSD log's IMU: gyro in deg/s, accelerometer in g (the firmware's 9.81 m/s²).
GYRO_UNIT, ACCEL_UNIT = np.pi / 180.0, 9.81


def load_decoder(repo: Path):
    """The checkout's own ``scripts/cfusdlog.py``, imported from the checkout."""
    path = repo / "scripts" / "cfusdlog.py"
    spec = importlib.util.spec_from_file_location("cfusdlog_checkout", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def stand_thrust_coefficient(repo: Path, vehicle: str) -> tuple[float, list[float]]:
    """c_T of the thrust stand (module docstring) and the per-file values (brushed)."""
    k = RPM_TO_RAD_S
    if vehicle == "brushed":
        base = repo / "system-id/data/cf21_bitcraze2021"
        forces, sums, per_file = [], [], []
        for name in ("cf2.1-stock-prop.csv", "cf21_stock2.csv"):
            d = np.genfromtxt(base / name, delimiter=",", names=True)
            f = d["weightg"] * 1e-3 * GRAVITY
            s = sum((d[f"rpm{i}"] * k) ** 2 for i in range(1, 5))
            forces.append(f)
            sums.append(s)
            per_file.append(float(f @ s / (s @ s)))
        f, s = np.concatenate(forces), np.concatenate(sums)
        return float(f @ s / (s @ s)), per_file
    base = repo / "brushless_calibration/data"
    log = np.genfromtxt(base / "data_calib_brushless.csv", delimiter=",", names=True)
    scale = np.genfromtxt(base / "manual_data_calib_brushless.csv", delimiter=",", names=True)
    f = scale["weightg"] * 1e-3 * GRAVITY
    n = np.array([np.median(log["rpm4"][log["pwm"] == p]) for p in scale["rpm"]]) * k
    s = 4.0 * n**2
    return float(f @ s / (s @ s)), []


def stand_top_speed(repo: Path, vehicle: str) -> float:
    """The highest rotor speed the stand data record, rad/s (the vehicle's n_max)."""
    if vehicle == "brushed":
        d = np.genfromtxt(repo / "system-id/data/cf21_bitcraze2021/cf2.1-stock-prop.csv",
                          delimiter=",", names=True)
        return float(max(d[f"rpm{i}"].max() for i in range(1, 5)) * RPM_TO_RAD_S)
    d = np.genfromtxt(repo / "brushless_calibration/data/data_calib_brushless.csv",
                      delimiter=",", names=True)
    top = d["pwm"].max()
    return float(np.median(d["rpm4"][d["pwm"] == top]) * RPM_TO_RAD_S)


def prior_theta(mass: float, n_max: float) -> np.ndarray:
    """The generic prior θ of the module docstring."""
    c_t = 2.0 * mass * GRAVITY / (4.0 * n_max**2)
    side, height = 2.0 * ARM, 0.02
    j_xy = mass * (side**2 + height**2) / 12.0
    j_z = mass * 2.0 * side**2 / 12.0
    return np.array([c_t, 0.01, 0.01 * c_t, j_xy, j_xy, j_z])


def thirty_prior(reference: np.ndarray, generic: np.ndarray) -> np.ndarray:
    """θ 30 % off the reference (`PRIOR_FACTORS`); c_D and c_M, which have no
    reference, from the generic prior's values by the same factors."""
    base = np.where(np.isfinite(reference), reference, generic)
    return base * PRIOR_FACTORS


def vehicle_toml(name: str, mass: float, theta: np.ndarray, n_max: float) -> str:
    """The vehicle file of the module docstring, written by the project's TOML writer."""
    base = load_vehicle("micro_quad")
    a = ARM / np.sqrt(2.0)
    rotors = tuple(RotorConfig((float(sx * a), float(sy * a), 0.0), d)
                   for (sx, sy), d in LAYOUT)
    config = replace(base, name=name, mass=mass, rotors=rotors, source="",
                     limits=replace(base.limits, rotor_speed_max=float(n_max)))
    return vehicle_to_toml(config.with_parameters(np.asarray(theta, float)))


def imu_columns(ff: dict) -> tuple[np.ndarray, np.ndarray]:
    """The on-board gyro (rad/s) and specific force (m/s²), body FLU, shape (N, 3) each."""
    gyro = np.column_stack([ff[f"gyro.{a}"] for a in "xyz"]) * GYRO_UNIT
    accel = np.column_stack([ff[f"acc.{a}"] for a in "xyz"]) * ACCEL_UNIT
    return gyro, accel


def convert(decoded: dict, directory: Path, imu: bool = True) -> tuple[Path, int, float]:
    """Write ``pose.csv`` from the decoded ``fixedFrequency`` event, with the IMU columns
    unless ``imu`` is False; (path, rows, duration)."""
    ff = decoded["fixedFrequency"]
    t = np.asarray(ff["timestamp"], float) * 1e-3
    keep = np.concatenate([[True], np.diff(t) > 1e-6])
    p = np.column_stack([ff[f"stateEstimate.{a}"] for a in "xyz"])
    q = np.column_stack([ff[f"stateEstimate.q{a}"] for a in "wxyz"])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    n = np.column_stack([ff[f"rpm.m{i}"] for i in range(1, 5)]) * RPM_TO_RAD_S
    path = directory / "pose.csv"
    with PoseLogWriter(path, 4, imu=imu) as writer:
        if imu:
            gyro, accel = imu_columns(ff)
            writer.write_rows(t[keep], p[keep], q[keep], n[keep], gyro=gyro[keep],
                              accel=accel[keep])
        else:
            writer.write_rows(t[keep], p[keep], q[keep], n[keep])
    return path, int(keep.sum()), float(t[-1] - t[0])


def _scored(value: np.ndarray, sigma: np.ndarray, reference: np.ndarray) -> dict:
    with np.errstate(invalid="ignore", divide="ignore"):
        error = value / reference - 1.0
        covered = np.abs(value - reference) <= Z95 * sigma
    return {"value": value.tolist(), "sigma": sigma.tolist(),
            "error": [None if not np.isfinite(e) else float(e) for e in error],
            "covered": [None if not np.isfinite(r) else bool(c)
                        for r, c in zip(reference, covered, strict=True)]}


def run_tool(pose: Path, vehicle: Path, reference: np.ndarray) -> dict:
    """``mavsysid estimate`` as a user runs it (a subprocess writing ``estimate.json``).

    In the shape of `run_balance`'s row: the answer per parameter (value, σ, status), the
    balance's data value where a parameter is not determined, its choices, held-out check
    and combinations; or the exit code and the one-line message.
    """
    t0 = time.perf_counter()
    out_json = pose.parent / "estimate.json"
    proc = subprocess.run([sys.executable, "-m", "mavsysid", "estimate", str(pose),
                           "--vehicle", str(vehicle), "-o", str(out_json), "-q"],
                          capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode:
        lines = proc.stderr.strip().splitlines()
        return {"code": proc.returncode, "message": lines[-1] if lines else "",
                "stderr_lines": len(lines), "seconds": seconds,
                "traceback": "Traceback" in proc.stderr}
    doc = json.loads(out_json.read_text(encoding="utf-8"))
    params = doc["parameters"]
    value = np.array([params[n]["value"] for n in PARAMETER_NAMES], float)
    sigma = np.array([params[n]["sigma"] for n in PARAMETER_NAMES], float)
    status = [params[n].get("status", "determined") for n in PARAMETER_NAMES]
    out = _scored(value, sigma, reference)
    balance = doc.get("balance")
    data_value, data_sigma = value.copy(), sigma.copy()
    if balance is not None:
        for k, n in enumerate(PARAMETER_NAMES):
            if status[k] != "determined":
                data_value[k] = balance["parameters"][n]["data_value"] or np.nan
                data_sigma[k] = balance["parameters"][n]["data_sigma"] or np.nan
    choices = (balance or {}).get("choices") or {}
    combos = (balance or {}).get("combinations") or {}
    out.update(
        code=0, seconds=seconds, status=status,
        source=[params[n].get("source") for n in PARAMETER_NAMES],
        data=_scored(data_value, data_sigma, reference),
        filter_refusal=doc.get("filter_refusal"), mismatch=doc.get("mismatch", []),
        sensors=next((n for n in doc.get("notes", []) if "the balance read" in n), None),
        window_s=choices.get("window_s"), delay_s=choices.get("delay_s") or 0.0,
        roll_pitch_band=choices.get("roll_pitch_band_hz"),
        combinations=[(combos.get(c) or {}).get("value") or np.nan
                      for c in ("c_M/j_z", "J_r/j_z")],
        combination_sigma=[(combos.get(c) or {}).get("sigma") or np.nan
                           for c in ("c_M/j_z", "J_r/j_z")],
        holdout=doc.get("holdout"), noise_met=doc.get("noise_met"))
    return out


def run_diagnose_tool(pose: Path, vehicle: Path) -> dict:
    """``mavsysid diagnose`` as a user runs it after ``estimate`` (its ``estimate.json``).

    The row: exit code, seconds, the named effects, and the held-out RMSE ratios to the
    prior model's (force, angular acceleration) before and after them; or the one-line
    message.
    """
    t0 = time.perf_counter()
    out_json = pose.parent / "diagnosis.json"
    estimate = pose.parent / "estimate.json"
    proc = subprocess.run([sys.executable, "-m", "mavsysid", "diagnose", str(pose),
                           "--vehicle", str(vehicle), "-o", str(out_json), "-q",
                           *(["--estimate", str(estimate)] if estimate.exists() else [])],
                          capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode:
        lines = proc.stderr.strip().splitlines()
        return {"code": proc.returncode, "message": lines[-1] if lines else "",
                "seconds": seconds, "traceback": "Traceback" in proc.stderr}
    doc = json.loads(out_json.read_text(encoding="utf-8"))
    held = doc["gap"].get("held_out") or {}
    return {"code": 0, "seconds": seconds, "effects": [e["name"] for e in doc["effects"]],
            "held_out": {k: v for k, v in held.items() if k.endswith(("_before", "_after"))}}


def refuse_empty(directory: Path, vehicle: Path) -> dict:
    """What ``mavsysid estimate`` says about an empty pose log (a recording that failed)."""
    pose = directory / "pose.csv"
    pose.write_text("", encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "mavsysid", "estimate", str(pose),
                           "--vehicle", str(vehicle), "-q"],
                          capture_output=True, text=True, check=False)
    lines = proc.stderr.strip().splitlines()
    return {"code": proc.returncode, "message": lines[-1] if lines else "",
            "stderr_lines": len(lines)}


def _flight(pose: Path, config) -> tuple[FlightData, str | None]:
    """The flight as `estimate` reads it; if the reader refuses, the pose log as written.

    The second value is the reader's refusal (then the balance runs on the unchecked log,
    to show what the estimator itself does with it).
    """
    try:
        return load_flight(pose, config), None
    except LogFormatError as error:
        log = read_pose_log(pose, config.rotor_count)
        return (FlightData(log.t, log.position, log.quaternion, log.rotor_speeds, str(pose)),
                str(error).splitlines()[0])


def run_balance(pose: Path, vehicle: Path, reference: np.ndarray) -> dict:
    """`fit_wrench_balance` on the converted flight, read as `estimate` reads it."""
    t0 = time.perf_counter()
    config = load_vehicle(vehicle)
    flight, reader_refusal = _flight(pose, config)
    try:
        result = fit_wrench_balance(flight, config)
    except MavsysidError as error:
        return {"code": exit_code(error), "message": str(error).splitlines()[0],
                "reader_refusal": reader_refusal, "seconds": time.perf_counter() - t0}
    out = _scored(result.estimate.value, result.estimate.sigma, reference)
    parts = result.sigma_parts
    c = result.choices
    out.update(
        code=0, seconds=time.perf_counter() - t0, status=list(result.status[:6]),
        reader_refusal=reader_refusal,
        data=_scored(result.data.value, widened_sigma(parts), reference),
        sigma_parts=parts.tolist(), combinations=result.data.combinations.tolist(),
        combination_sigma=result.combination_sigma.tolist(),
        window_s=c.window, delay_s=c.delay, delay_sigma_s=result.delay_sigma,
        roll_pitch_band=None if c.roll_pitch is None else [c.roll_pitch.low, c.roll_pitch.high],
        yaw_band=None if c.yaw is None else [c.yaw.low, c.yaw.high],
        force_cut_hz=None if c.force is None else c.force.high,
        holdout=None if result.holdout is None else result.holdout.as_dict())
    return out


def run_flight(job: tuple) -> dict:
    """Decode, convert and estimate one flight (a worker's task)."""
    repo, vehicle, path, references, prior, n_max, library, diagnose, imu = job
    row = {"flight": path.name, "vehicle": vehicle}
    with tempfile.TemporaryDirectory(prefix="cf-") as tmp:
        toml = Path(tmp) / f"{vehicle}.toml"
        toml.write_text(vehicle_toml(f"cf21_{vehicle}", VEHICLES[vehicle][2], prior, n_max),
                        encoding="utf-8")
        if path.stat().st_size == 0:
            return {**row, "skipped": "empty file (a recording that failed)",
                    "tool": refuse_empty(Path(tmp), toml)}
        decoded = load_decoder(repo).decode(str(path))
        if not decoded or "fixedFrequency" not in decoded:
            return {**row, "skipped": "the decoder found no fixedFrequency event"}
        pose, rows, duration = convert(decoded, Path(tmp), imu)
        row.update(rows=rows, duration=duration, imu=imu)
        row["balance"] = run_tool(pose, toml, references)
        if library:
            row["library"] = run_balance(pose, toml, references)
        if diagnose:
            row["diagnose"] = run_diagnose_tool(pose, toml)
    return row


def _flights(repo: Path, patterns: list[str]) -> list[tuple[str, Path]]:
    out = []
    for vehicle, (folder, prefix, _) in VEHICLES.items():
        for path in sorted((repo / folder).glob(f"{prefix}*")):
            if path.suffix or not path.is_file():
                continue
            if not patterns or any(p in path.name for p in patterns):
                out.append((vehicle, path))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, required=True,
                        help="a checkout of IMRCLab/crazyflie-data-collection")
    parser.add_argument("--json", type=Path, help="write the per-flight results here")
    parser.add_argument("--flights", default="", help="comma-separated name filters")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--markdown", type=Path, help="write the per-flight table (Markdown)")
    parser.add_argument("--library", action="store_true",
                        help="also run the library's balance alone (`fit_wrench_balance`)")
    parser.add_argument("--diagnose", action="store_true",
                        help="also run `mavsysid diagnose` on each flight after `estimate`")
    parser.add_argument("--prior", choices=("generic", "thirty"), default="generic",
                        help="the vehicle file's θ: generic (default) or 30 %% off the "
                             "references (c_T, c_M × 1.3; c_D, J × 0.7)")
    parser.add_argument("--no-imu", action="store_true",
                        help="write pose.csv without the on-board IMU's columns")
    args = parser.parse_args()
    repo = args.repo.resolve()
    refs, stand, jobs = {}, {}, []
    for vehicle in VEHICLES:
        c_t, per_file = stand_thrust_coefficient(repo, vehicle)
        n_max = stand_top_speed(repo, vehicle)
        stand[vehicle] = {"c_T": c_t, "per_file": per_file, "n_max": n_max,
                          "prior": prior_theta(VEHICLES[vehicle][2], n_max).tolist()}
        refs[vehicle] = np.array([c_t, np.nan, np.nan, *FOERSTER_J])
        if args.prior == "thirty":
            stand[vehicle]["prior"] = thirty_prior(refs[vehicle],
                                                   np.array(stand[vehicle]["prior"])).tolist()
        stand[vehicle]["prior_kind"] = args.prior
        stand[vehicle]["imu"] = not args.no_imu
    for vehicle, path in _flights(repo, [p for p in args.flights.split(",") if p]):
        prior = np.array(stand[vehicle]["prior"])
        jobs.append((repo, vehicle, path, refs[vehicle], prior, stand[vehicle]["n_max"],
                     args.library, args.diagnose, not args.no_imu))
    print(f"references: {json.dumps(stand)}")
    rows = []
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for row in pool.map(run_flight, jobs):  # in order; each row kept as it arrives
            rows.append(row)
            print(f"done {row['flight']}", file=sys.stderr, flush=True)
            if args.json:
                args.json.write_text(json.dumps({"references": stand, "flights": rows},
                                                indent=1), encoding="utf-8")
    for row in rows:
        if "diagnose" in row:
            print(f"diagnose {row['flight']}: {json.dumps(row['diagnose'])}")
    print_table(rows, PARAMETER_NAMES)
    print_summary(rows, refs)
    if args.json:
        args.json.write_text(json.dumps({"references": stand, "flights": rows}, indent=1),
                             encoding="utf-8")
    if args.markdown:
        args.markdown.write_text(markdown_table(rows), encoding="utf-8")


if __name__ == "__main__":
    main()
