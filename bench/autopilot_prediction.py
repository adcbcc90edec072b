"""The autopilot-loop model's prediction against flown flights: ArduCopter SITL and
`mavsysid sim`.

For each flight the trajectory that was streamed (``trajectory.json`` of the flight
directory) is flown by `mavsysid.vehicle.autopilot_loop.fly` with the autopilot's own
parameters (SITL: every PARM of its DataFlash log; `mavsysid sim`: its parameter table),
starting at the trajectory's start as the streamer's ``meta.json`` places it on the
autopilot's clock (``trajectory_window.start``), refined by the lag that best lines up the
flown position with the setpoints. Compared with what was flown (``flight.tlog``:
LOCAL_POSITION_NED, ATTITUDE_QUATERNION, SERVO_OUTPUT_RAW through the vehicle's motor
curve; `mavsysid sim`: its ``truth.csv``): position, attitude (angle between the
quaternions), yaw and rotor speeds, each as RMS, max and the lag that best aligns the
prediction with the flight (cross-correlation, positive: the flight later) — beside the
same numbers for the setpoints themselves (the exact-tracking assumption: the flatness
map of the trajectory).

    # fly on a fresh SITL per kind and seed (planned: `mavsysid experiment`; practitioner:
    # the Lissajous with yaw; model: `experiment --autopilot-model`), then compare
    nice python bench/autopilot_prediction.py --sitl --seeds 1 [--kinds planned model] \
        --work DIR
    # compare flights already flown on SITL (DIR as bench/sitl_practitioner.py leaves it)
    python bench/autopilot_prediction.py --report DIR
    # against `mavsysid sim` (lock-step), ArduPilot and PX4 personalities
    nice python bench/autopilot_prediction.py --sim ardupilot px4 --work DIR
    # the figure of one flight
    python bench/autopilot_prediction.py --figure FLIGHT_DIR --out docs/images/x.png
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

VEHICLE = "sitl_quad"


@dataclass
class Flown:
    """A flight as logged, on the trajectory's clock (s from its start), world ENU."""

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_t: np.ndarray
    rotor_speeds: np.ndarray


def dataflash_parameters(path: Path) -> dict[str, float]:
    """Every PARM of a DataFlash log (the last value of each name)."""
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(path))
    values: dict[str, float] = {}
    while (m := log.recv_match(type="PARM")) is not None:
        values[m.Name] = float(m.Value)
    return values


def read_flown_tlog(flight: Path, config, start: float) -> Flown:
    """Pose and rotor speeds of ``flight.tlog`` in ENU/FLU and the config's rotor order."""
    from mavsysid.estimation.readers.autopilot_logs import read_autopilot_log
    from mavsysid.formats.tlog import read_tlog

    streams = read_autopilot_log(read_tlog, flight / "flight.tlog", config)
    pose, rotors = streams.pose, streams.rotors
    speeds = np.column_stack([r.values for r in rotors])
    return Flown(pose.t - start, pose.values[:, :3], pose.values[:, 3:7],
                 rotors[0].t - start, speeds)


def read_flown_truth(flight: Path, start: float) -> Flown:
    """The true pose and rotor speeds of a simulated flight's ``truth.csv``."""
    import pandas as pd

    truth = pd.read_csv(flight / "truth.csv")
    t = truth["t"].to_numpy() - start
    pos = truth[["x", "y", "z"]].to_numpy()
    quat = truth[["qw", "qx", "qy", "qz"]].to_numpy()
    speed_columns = [c for c in truth.columns if c.startswith("n") and c[1:].isdigit()]
    return Flown(t, pos, quat, t, truth[speed_columns].to_numpy())


def quaternion_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between attitudes, rad, row by row: |Log(a⁻¹ ⊗ b)|."""
    from mavsysid.vehicle.rotation import quat_conjugate, quat_log, quat_multiply

    return np.linalg.norm(quat_log(quat_multiply(quat_conjugate(a), b)), axis=-1)


def yaw_of(q: np.ndarray) -> np.ndarray:
    """Heading of the body x axis, rad, unwrapped."""
    from mavsysid.vehicle.rotation import quat_yaw

    return np.unwrap(quat_yaw(q))


def lag_of(reference: np.ndarray, flown: np.ndarray, step: float, most: float = 1.0) -> float:
    """The delay (s) of ``flown`` behind ``reference`` (1-D, same grid) that best aligns
    their variations (largest cross-correlation within ±``most`` s)."""
    a, b = reference - reference.mean(), flown - flown.mean()
    shifts = np.arange(-int(most / step), int(most / step) + 1)
    scores = [np.dot(a[max(0, -s):len(a) - max(0, s)], b[max(0, s):len(b) - max(0, -s)])
              for s in shifts]
    return float(shifts[int(np.argmax(scores))] * step)


def channel_stats(error: np.ndarray) -> dict[str, float]:
    """RMS and max of an error (rows: samples; columns: components summed as a norm)."""
    norm = np.linalg.norm(error.reshape(len(error), -1), axis=1)
    return {"rms": float(np.sqrt(np.mean(norm**2))), "max": float(np.max(norm))}


def received_setpoints(dataflash: Path, trajectory, start: float, rate: float) -> np.ndarray:
    """The setpoints as ArduCopter received them (GUIP: its clock, position, velocity,
    acceleration) over the trajectory, rows as `fly_setpoints` takes them (t from the
    trajectory's start on the autopilot's clock); the yaw and yaw rate of the trajectory
    sample each one is (the nearest in position to its expected index)."""
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(dataflash))
    rows = []
    while (m := log.recv_match(type="GUIP")) is not None:
        rows.append((m.TimeUS * 1e-6 - start, m.pY, m.pX, m.pZ, m.vY, m.vX, m.vZ,
                     m.aY, m.aX, m.aZ))
    got = np.array(rows)
    got = got[(got[:, 0] >= -0.5 / rate) & (got[:, 0] <= trajectory.duration + 0.5)]
    k_all = np.arange(0, int(trajectory.duration * rate) + 1)
    samples = trajectory.flat_outputs(k_all / rate)
    out, last = [], 0
    for row in got:
        expected = round(float(row[0]) * rate)
        window = np.arange(max(last, expected - 15), min(k_all[-1], expected + 15) + 1)
        if window.size == 0:
            continue
        k = int(window[np.argmin(np.linalg.norm(samples.position[window] - row[1:4], axis=1))])
        last = k
        out.append([*row, samples.yaw[k], samples.yaw_rate[k]])
    return np.array(out)


def compare(trajectory, flown: Flown, loop, config, settle: float = 0.5,
            received: np.ndarray | None = None) -> dict:
    """Prediction and setpoints against the flown flight over the trajectory (plus
    ``settle`` s), on the flight's pose times; the prediction from the setpoints as the
    autopilot ``received`` them when given (`received_setpoints`), else from the
    trajectory at the streamer's nominal rate."""
    from mavsysid.vehicle.autopilot_loop import fly, fly_setpoints
    from mavsysid.vehicle.flatness import flat_to_state
    from mavsysid.vehicle.rotation import wrap_angle

    span = trajectory.duration + settle
    if received is None:
        flight = fly(loop, trajectory, config, sample_step=0.0025, duration=span)
    else:
        shift = float(received[0, 0])
        rows = received.copy()
        rows[:, 0] -= shift
        flight = fly_setpoints(loop, rows, config, sample_step=0.0025, duration=span)
        flight = replace(flight, times=flight.times + shift)
    keep = (flown.t >= 0.0) & (flown.t <= span)
    t = flown.t[keep]
    idx = np.clip(np.searchsorted(flight.times, t), 0, len(flight.times) - 1)
    flat = flat_to_state(trajectory.flat_outputs(t), config)
    out = {"duration": trajectory.duration}
    pos = flown.position[keep]
    q = flown.quaternion[keep]
    step = float(np.median(np.diff(t)))
    for name, p_pos, p_q in (("model", flight.position[idx], flight.quaternion[idx]),
                             ("setpoints", flat.position, flat.quaternion)):
        yaw_err = wrap_angle(yaw_of(q) - yaw_of(p_q))
        out[name] = {
            "position_m": channel_stats(pos - p_pos),
            "attitude_deg": {k: float(np.degrees(v)) for k, v in
                             channel_stats(quaternion_angle(q, p_q)[:, None]).items()},
            "yaw_deg": {k: float(np.degrees(v)) for k, v in
                        channel_stats(yaw_err[:, None]).items()},
            "lag_position_s": float(np.mean([lag_of(p_pos[:, i], pos[:, i], step)
                                             for i in range(3)])),
            "lag_yaw_s": lag_of(yaw_of(p_q), yaw_of(q), step),
        }
    rk = (flown.rotor_t >= 0.0) & (flown.rotor_t <= span)
    rt = flown.rotor_t[rk]
    ridx = np.clip(np.searchsorted(flight.times, rt), 0, len(flight.times) - 1)
    rflat = flat_to_state(trajectory.flat_outputs(rt), config)
    rstep = float(np.median(np.diff(rt)))
    for name, speeds in (("model", flight.rotor_speeds[ridx]),
                         ("setpoints", rflat.rotor_speeds)):
        err = flown.rotor_speeds[rk] - speeds
        out[name]["rotor_rad_s"] = {
            "rms": float(np.sqrt(np.mean(err**2))), "max": float(np.max(np.abs(err))),
            "lag_s": float(np.mean([lag_of(speeds[:, i], flown.rotor_speeds[rk][:, i], rstep)
                                    for i in range(speeds.shape[1])]))}
    return out


def sitl_flight(kind_dir: Path):
    """(flight directory, DataFlash log) of one SITL flight bench/sitl_practitioner.py left."""
    flights = [p for p in (kind_dir / "logs").iterdir() if p.is_dir()]
    logs = sorted((kind_dir / "sitl" / "logs").glob("*.BIN"))
    return (flights[0] if flights else None), (logs[-1] if logs else None)


def compare_sitl(flight: Path, dataflash: Path) -> dict:
    """`compare` for one SITL flight, its loop set from the log's parameters."""
    from mavsysid.formats.trajectory_file import read_trajectory
    from mavsysid.vehicle.autopilot_loop import AutopilotLoop
    from mavsysid.vehicle.config import load_vehicle

    config = load_vehicle(VEHICLE)
    meta = json.loads((flight / "meta.json").read_text())
    trajectory = read_trajectory(flight / "trajectory.json").trajectory
    rate = meta["stream"]["setpoint_rate_hz"]
    loop = AutopilotLoop.from_parameters("ardupilot", dataflash_parameters(dataflash), rate)
    start = meta["trajectory_window"]["start"]
    flown = read_flown_tlog(flight, config, start)
    out = compare(trajectory, flown, loop, config)
    out["received"] = compare(trajectory, flown, loop, config,
                              received=received_setpoints(dataflash, trajectory, start,
                                                          rate))["model"]
    return out


def fly_model_planned(connect: str, seed: int, args: argparse.Namespace, logs: Path) -> str:
    """``mavsysid experiment --autopilot-model`` (else as `fly_planned`); its output."""
    import subprocess

    from mavsysid.planner.settings import PlannerSettings

    from bench.sitl_practitioner import box_text

    done = subprocess.run(
        [sys.executable, "-m", "mavsysid", "experiment", "--connect", connect,
         "--vehicle", VEHICLE, "--budget", f"{args.budget:g}", "--samples",
         str(args.samples), "--refine-steps", str(args.refine_steps), "--seed", str(seed),
         "--box", box_text(PlannerSettings.box), "--prearm-timeout", "300",
         "--autopilot-model", "--log-dir", str(logs)], capture_output=True, text=True,
        check=False)
    return f"exit {done.returncode}\n{done.stdout}{done.stderr}"


def fly_sitl(work: Path, seeds: list[int], kinds: list[str]) -> None:
    """Flights per seed and kind on a fresh SITL each, kept under ``work/KIND/seedS``:
    ``planned`` and ``practitioner`` as `bench/sitl_practitioner.py` flies them, ``model``
    planned on the autopilot's predicted flight (`fly_model_planned`)."""
    from bench.sitl_practitioner import SITL_PARMS, fly_planned, fly_practitioner
    from tests.support.sitl import running_sitl

    settings = argparse.Namespace(budget=20.0, samples=200, refine_steps=300)
    fliers = {"planned": lambda c, s, logs: fly_planned(c, s, settings, logs),
              "practitioner": lambda c, s, logs: fly_practitioner(c, settings, logs),
              "model": lambda c, s, logs: fly_model_planned(c, s, settings, logs)}
    for seed in seeds:
        for kind in kinds:
            where = work / kind / f"seed{seed}"
            with running_sitl(where / "sitl", defaults=[SITL_PARMS], model="x") as sitl:
                text = fliers[kind](sitl.connect, seed, where / "logs")
            (where / "run.out").write_text(text)
            print(f"{kind} seed {seed}: {text.splitlines()[0]}", flush=True)


def fly_sim(work: Path, autopilot: str, trajectory_file: Path) -> Path:
    """``trajectory_file`` streamed to `mavsysid sim --autopilot AUTOPILOT` (lock-step, no
    noise, its truth logged); the flight directory, with ``truth.csv`` copied in."""
    import shutil

    from mavsysid.flight.loopback_ports import free_udp_port

    from tests.support.stream_flights import SimProcess, flight_dir, run_stream

    port = free_udp_port()
    truth = work / "truth"
    with SimProcess(work / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--vehicle",
                    VEHICLE, "--autopilot", autopilot, "--speedup", "4", "--no-noise",
                    "--truth-log", str(truth)) as sim:
        sim.wait_ready(timeout=300)
        done = run_stream(trajectory_file, "--connect", f"udp:127.0.0.1:{port}", "--vehicle",
                          VEHICLE, "--speedup", "4", "--log-dir", str(work / "logs"),
                          cwd=work, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"stream exit {done.returncode}: {done.stderr[-2000:]}")
    flight = flight_dir(work / "logs")
    shutil.copy(truth / "truth.csv", flight / "truth.csv")
    shutil.copy(trajectory_file, flight / "trajectory.json")
    return flight


def compare_sim(flight: Path, autopilot: str) -> dict:
    """`compare` for a `mavsysid sim` flight, its loop set from the sim's parameter table."""
    from mavsysid.flight.autopilot_modes import Autopilot
    from mavsysid.flight.simvehicle.params import default_parameters
    from mavsysid.formats.trajectory_file import read_trajectory
    from mavsysid.vehicle.autopilot_loop import AutopilotLoop
    from mavsysid.vehicle.config import load_vehicle

    config = load_vehicle(VEHICLE)
    meta = json.loads((flight / "meta.json").read_text())
    table = default_parameters(Autopilot[autopilot.upper()], config)
    values = {table.at(i).name: table.at(i).value for i in range(len(table))}
    loop = AutopilotLoop.from_parameters(autopilot, values, meta["stream"]["setpoint_rate_hz"])
    trajectory = read_trajectory(flight / "trajectory.json").trajectory
    flown = read_flown_truth(flight, meta["trajectory_window"]["start"])
    return compare(trajectory, flown, loop, config)


def sim_flights(work: Path, autopilots: list[str]) -> None:
    """The practitioner's figure (the SITL limits) and a planned flight of the SITL
    bench, each streamed to `mavsysid sim` with each autopilot personality."""
    from mavsysid.experiments.baselines import practitioner_excitation
    from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
    from mavsysid.pipeline.plan import autopilot_limits
    from mavsysid.planner.settings import PlannerSettings
    from mavsysid.vehicle.config import load_vehicle

    config = load_vehicle(VEHICLE)
    limits = autopilot_limits(REPO / "bench" / "arducopter_stock_limits.parm")[1]
    settings = PlannerSettings(budget=20.0, autopilot_limits=limits)
    work.mkdir(parents=True, exist_ok=True)
    figure = work / "practitioner.json"
    write_trajectory_file(figure, trajectory_file_for(
        practitioner_excitation(config, settings).trajectory, config, "practitioner",
        settings.box))
    for autopilot in autopilots:
        flight = fly_sim(work / autopilot, autopilot, figure)
        report_rows(f"sim {autopilot} practitioner", compare_sim(flight, autopilot))


def figure(kind_dir: Path, out: Path) -> None:
    """Flown, predicted and set: position, yaw and rotor 1 of one SITL flight."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mavsysid.formats.trajectory_file import read_trajectory
    from mavsysid.vehicle.autopilot_loop import AutopilotLoop, fly
    from mavsysid.vehicle.config import load_vehicle
    from mavsysid.vehicle.flatness import flat_to_state

    flight, dataflash = sitl_flight(kind_dir)
    config = load_vehicle(VEHICLE)
    meta = json.loads((flight / "meta.json").read_text())
    trajectory = read_trajectory(flight / "trajectory.json").trajectory
    loop = AutopilotLoop.from_parameters("ardupilot", dataflash_parameters(dataflash))
    flown = read_flown_tlog(flight, config, meta["trajectory_window"]["start"])
    keep = (flown.t >= 0.0) & (flown.t <= trajectory.duration + 0.5)
    rkeep = (flown.rotor_t >= 0.0) & (flown.rotor_t <= trajectory.duration + 0.5)
    flown = Flown(flown.t[keep], flown.position[keep], flown.quaternion[keep],
                  flown.rotor_t[rkeep], flown.rotor_speeds[rkeep])
    pred = fly(loop, trajectory, config, sample_step=0.01, duration=trajectory.duration + 0.5)
    flat = flat_to_state(trajectory.flat_outputs(pred.times), config)
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    at = np.interp
    for i, name in enumerate("xy"):
        axes[i].plot(flown.t, 100 * (flown.position[:, i] - at(flown.t, pred.times,
                                                                flat.position[:, i])),
                     "k", label="flown − set")
        axes[i].plot(pred.times, 100 * (pred.position[:, i] - flat.position[:, i]), "r",
                     label="predicted − set")
        axes[i].set_ylabel(f"{name} off the setpoint, cm")
    axes[0].legend(loc="upper right")
    axes[2].plot(flown.t, np.degrees(yaw_of(flown.quaternion)
                                     - at(flown.t, pred.times, yaw_of(flat.quaternion))), "k")
    axes[2].plot(pred.times, np.degrees(pred.yaw - yaw_of(flat.quaternion)), "r")
    axes[2].set_ylabel("yaw off the setpoint, °")
    axes[3].plot(flown.rotor_t, flown.rotor_speeds[:, 0], "k", label="flown (motor output)")
    axes[3].plot(pred.times, pred.rotor_speeds[:, 0], "r", label="predicted")
    axes[3].plot(pred.times, flat.rotor_speeds[:, 0], "b--", label="set (flatness)")
    axes[3].set_ylabel("rotor 1, rad/s")
    axes[3].legend(loc="upper right")
    axes[3].set_xlabel("trajectory time, s")
    axes[3].set_xlim(0.0, trajectory.duration + 0.5)
    fig.suptitle(f"ArduCopter SITL, {kind_dir.parent.name} {kind_dir.name}: flown against "
                 "the autopilot-loop prediction")
    fig.tight_layout()
    fig.savefig(out, dpi=80)


def report_rows(name: str, result: dict) -> None:
    """Print one flight's comparison, model and setpoints."""
    for kind in ("model", "received", "setpoints"):
        if kind not in result:
            continue
        r = result[kind]
        print(f"{name:28s} {kind:9s} pos {100 * r['position_m']['rms']:5.1f}/"
              f"{100 * r['position_m']['max']:5.1f} cm lag {r['lag_position_s']:+.3f} s | "
              f"att {r['attitude_deg']['rms']:4.1f}/{r['attitude_deg']['max']:4.1f}° | "
              f"yaw {r['yaw_deg']['rms']:4.1f}/{r['yaw_deg']['max']:5.1f}° lag "
              f"{r['lag_yaw_s']:+.3f} s | rotors {r['rotor_rad_s']['rms']:5.1f}/"
              f"{r['rotor_rad_s']['max']:5.1f} rad/s lag {r['rotor_rad_s']['lag_s']:+.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--report", type=Path, help="SITL flights bench/sitl_practitioner.py "
                        "left in this folder")
    parser.add_argument("--sitl", action="store_true", help="fly on SITL first (--work)")
    parser.add_argument("--sim", nargs="+", choices=("ardupilot", "px4"),
                        help="fly on mavsysid sim with these personalities (--work)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--kinds", nargs="+", choices=("planned", "practitioner", "model"),
                        default=["planned", "practitioner"], help="what to fly with --sitl")
    parser.add_argument("--work", type=Path)
    parser.add_argument("--figure", type=Path, help="a SITL flight's folder (KIND/seedS)")
    parser.add_argument("--out", type=Path, default=Path("autopilot_prediction.png"))
    args = parser.parse_args()
    if args.figure:
        figure(args.figure, args.out)
        return
    if args.sim:
        sim_flights(args.work, args.sim)
        return
    if args.sitl:
        fly_sitl(args.work, args.seeds, args.kinds)
        args.report = args.work
    if args.report:
        for kind_dir in sorted(args.report.glob("*/seed*")):
            flight, dataflash = sitl_flight(kind_dir)
            if flight is None or dataflash is None:
                continue
            report_rows(f"{kind_dir.parent.name} {kind_dir.name}", compare_sitl(flight,
                                                                                dataflash))


if __name__ == "__main__":
    main()
