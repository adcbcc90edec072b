"""Flights of an independent simulator (RotorPy) with one effect hidden each, as pose logs.

RotorPy 3.0 (MIT licence, https://github.com/spencerfolk/rotorpy) flies its own Crazyflie
2.0 model (`rotorpy.vehicles.crazyflie_params`: mass, inertia, k_eta, k_m, the rotor
drag k_d and induced-inflow k_z terms, both linear in rotor speed, and a 72 ms motor
lag) with its own SE(3) controller (`rotorpy.controllers.quadrotor_control.SE3Control`)
and integrator (`Multirotor.step`, scipy RK45) along mavsysid's excitation figure
(`mavsysid.flight.offline.excitation`, a 3-D Lissajous with yaw). Its motion-capture
model (`rotorpy.sensors.external_mocap.MotionCapture`) adds white pose noise of 0.5 mm
and 0.1° (σ at the log rate), the vehicle files' default. Its IMU model
(`rotorpy.sensors.imu.Imu`, at the centre of gravity, axes along the body's) gives the
true body rates and specific force, from RotorPy's own state derivative
(`Multirotor.statedot`), at every logged sample; the bench adds a constant bias per axis
drawn once per flight (σ `GYRO_BIAS_SIGMA` 0.005 rad/s, `ACCEL_BIAS_SIGMA` 0.1 m/s²) and
white noise (σ per sample `GYRO_SIGMA` 0.005 rad/s, `ACCEL_SIGMA` 0.04 m/s²), seeded
(`measured_imu`): the ``gyro_*`` and ``acc_*`` columns of ``pose.csv`` (``--no-imu``
leaves them out). Nothing of mavsysid's simulator is used; mavsysid only
supplies the reference figure and writes the files.

The variants hide one effect each from the vehicle file (`VARIANTS`):

* ``clean``: RotorPy as its parameter file says, rotor speeds as measured (RPM deck);
* ``motor_lag``: the same flight, but the log holds the *commanded* speeds (the motors
  follow with RotorPy's 72 ms lag);
* ``pose_delay``: the same flight, the pose reaches the log 20 ms late;
* ``marker_offset``: the same flight, the tracked point sits at (10, −10, 20) mm in the
  body frame;
* ``body_drag``: parasitic drag c_Dx = c_Dy = c_Dz (RotorPy's frame drag) of 5 % of the
  weight at 3 m/s;
* ``wind``: a steady wind of (1.2, −0.9) m/s (RotorPy's wind state);
* ``thrust_loss``: k_eta falling 8 % per 30 s during the flight (battery sag).

The vehicle file (`vehicle_toml`) holds the paper's model with the reference θ of
docs/rotorpy-bench.md, scaled by a seeded prior error; ``vehicle_declared.toml`` declares
RotorPy's rotor drag law instead (``--declared``); the reference goes to
``reference.json`` beside ``pose.csv``. Each flight is then estimated (``mavsysid
estimate``), diagnosed from that estimate (``mavsysid diagnose --estimate``) and
estimated with the named effects (``mavsysid estimate --auto-effects``; ``--no-auto``
skips it), through the library functions the commands call; the table gives each
parameter's error and z against the reference, what was named, the refusals and the
times. A pose log already in ``--out`` is reused.

    nice .venv/bin/python bench/rotorpy_flights.py --out /tmp/rotorpy-flights \
        [--duration 50] [--seed 0] [--declared] [--no-auto] [--no-estimate]
        [--reuse-estimate] [--json rows.json] [--no-imu] [--no-diagnose]

RotorPy is not a mavsysid dependency: ``.venv/bin/pip install --no-deps rotorpy==3.0.0``
(this bench needs only its numpy/scipy parts).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.poselog import PoseLogWriter
from mavsysid.vehicle.constants import GRAVITY

__all__ = [
    "HIDDEN",
    "VARIANTS",
    "evaluate",
    "fly",
    "fly_all",
    "format_row",
    "import_rotorpy",
    "measured",
    "measured_imu",
    "reference_theta",
    "vehicle_toml",
]

INSTALL = ("RotorPy is not installed: .venv/bin/pip install --no-deps rotorpy==3.0.0 "
           "(the bench needs only its numpy/scipy parts)")

VARIANTS = ("clean", "motor_lag", "body_drag", "wind", "pose_delay", "marker_offset",
            "thrust_loss")

#: The catalogue effect (`mavsysid.vehicle.model_effects`) each variant hides, and its truth.
HIDDEN: dict[str, tuple[str, dict[str, float]] | None] = {
    "clean": None,
    "motor_lag": ("motor_lag", {"tau": 0.072}),
    "body_drag": ("body_drag", {"k": 0.05 * 0.03 * GRAVITY / 9.0}),
    "wind": ("wind", {"x": 1.2, "y": -0.9}),
    "pose_delay": ("pose_delay", {"delay": 0.02}),
    "marker_offset": ("marker_offset", {"x": 0.01, "y": -0.01, "z": 0.02}),
    "thrust_loss": ("thrust_drift", {"rate": -0.08 / 30.0}),
}

#: Variants flown separately (their physics differ); the others re-log the clean flight.
_FLOWN = {"clean": "clean", "motor_lag": "clean", "pose_delay": "clean",
          "marker_offset": "clean", "body_drag": "body_drag", "wind": "wind",
          "thrust_loss": "thrust_loss"}

RATE_HZ = 500.0
POSITION_SIGMA = 0.0005
ATTITUDE_SIGMA = math.radians(0.1)
#: The IMU's white noise per logged sample and the σ of its constant biases per axis: the
#: vehicle files' defaults (`mavsysid.vehicle.config_types`), from real autopilot logs.
GYRO_SIGMA, ACCEL_SIGMA = 0.005, 0.04
GYRO_BIAS_SIGMA, ACCEL_BIAS_SIGMA = 0.005, 0.1


def import_rotorpy() -> dict[str, Any]:
    """RotorPy's vehicle, parameters, controller and motion capture; exit 2 if missing."""
    try:
        from rotorpy.controllers.quadrotor_control import SE3Control
        from rotorpy.sensors.external_mocap import MotionCapture
        from rotorpy.sensors.imu import Imu
        from rotorpy.vehicles.crazyflie_params import quad_params
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError:
        print(INSTALL, file=sys.stderr)
        raise SystemExit(2) from None
    return {"Multirotor": Multirotor, "params": quad_params, "SE3Control": SE3Control,
            "MotionCapture": MotionCapture, "Imu": Imu}


def hover_speed(params: dict[str, Any]) -> float:
    """Rotor speed of hover, rad/s: k_eta n² = m g / rotors."""
    return math.sqrt(params["mass"] * GRAVITY / (params["num_rotors"] * params["k_eta"]))


def reference_theta(params: dict[str, Any]) -> np.ndarray:
    """θ = [c_T, c_D, c_M, j_x, j_y, j_z] equivalent to RotorPy's parameters, SI.

    c_T = k_eta, c_M = k_m, J = diag(Ixx, Iyy, Izz). RotorPy's in-plane rotor drag is
    −k_d n v_hub; the paper's is −c_T n² c_D v_hub: the two are equal in hover (n = n_h)
    for c_D = k_d / (k_eta n_h). RotorPy's vertical term −k_z n v_hub,z has no
    counterpart in the paper's model.
    """
    n_h = hover_speed(params)
    return np.array([params["k_eta"], params["k_d"] / (params["k_eta"] * n_h), params["k_m"],
                     params["Ixx"], params["Iyy"], params["Izz"]])


def _rotors(params: dict[str, Any]) -> list[tuple[np.ndarray, int]]:
    """Rotor positions (body FLU, m) and mavsysid directions in RotorPy's order.

    RotorPy's yaw moment is +dir k_m n² about z_B; mavsysid's ε = +1 gives −c_M n², so
    ε = −dir.
    """
    return [(np.asarray(params["rotor_pos"][key], float), -int(d))
            for key, d in zip(params["rotor_pos"], params["rotor_directions"], strict=True)]


def vehicle_toml(params: dict[str, Any], prior: np.ndarray, name: str,
                 drag: tuple[float, float] | None = None) -> str:
    """The vehicle file: RotorPy's mass and geometry, the paper's model with θ = ``prior``.

    With ``drag`` = (k, k_z) it declares RotorPy's rotor drag law instead of the paper's
    quadratic one: ``[effects.rotor_drag_linear]`` at those values and c_D = 0.
    """
    lines = [f'# RotorPy 3.0 Crazyflie 2.0 (crazyflie_params), written by {Path(__file__).name}.',
             '# θ is the prior, not the reference (reference.json).',
             f'name = "{name}"', f"mass = {params['mass']!r}", ""]
    for position, direction in _rotors(params):
        lines += ["[[rotors]]", f"position = [{', '.join(repr(float(x)) for x in position)}]",
                  f"direction = {direction:+d}", ""]
    v = [repr(float(x)) for x in prior]
    if drag is not None:
        v[1] = "0.0"
    lines += ["[parameters]", f"c_T = {v[0]}", f"c_D = {v[1]}", f"c_M = {v[2]}",
              f"J = [{v[3]}, {v[4]}, {v[5]}]", "",
              "[limits]", f"rotor_speed_max = {float(params['rotor_speed_max'])!r}", "",
              "[motor]", f"time_constant = {float(params['tau_m'])!r}", "",
              "[noise]", f"position_sigma = {POSITION_SIGMA!r}",
              f"attitude_sigma = {ATTITUDE_SIGMA!r}", f"gyro_sigma = {GYRO_SIGMA!r}",
              f"accel_sigma = {ACCEL_SIGMA!r}", f"gyro_bias_sigma = {GYRO_BIAS_SIGMA!r}",
              f"accel_bias_sigma = {ACCEL_BIAS_SIGMA!r}", ""]
    if drag is not None:
        lines += ["[effects.rotor_drag_linear]", f"k = {float(drag[0])!r}",
                  f"k_z = {float(drag[1])!r}", ""]
    return "\n".join(lines)


@dataclass(frozen=True)
class TruthRecord:
    """One RotorPy flight at the log rate: truth pose, actual and commanded rotor speeds,
    and the IMU's true readings (body rates, specific force; body FLU, at the CoG)."""

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray  # [w, x, y, z], body → world
    rotor_speeds: np.ndarray
    commands: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray


def params_for(base: dict[str, Any], flown: str) -> dict[str, Any]:
    """RotorPy's parameters for a flight of kind ``flown``: its parasitic drag, translational
    lift, flapping and motor noise off, the hidden body drag on where ``flown`` has it."""
    params = copy.deepcopy(base)
    params.update(c_Dx=0.0, c_Dy=0.0, c_Dz=0.0, k_h=0.0, k_flap=0.0, motor_noise_std=0.0)
    if flown == "body_drag":
        k = HIDDEN["body_drag"][1]["k"]  # type: ignore[index]
        params.update(c_Dx=k, c_Dy=k, c_Dz=k)
    return params


def _flat(trajectory: Any, t: float) -> dict[str, Any]:
    f = trajectory.flat_outputs(np.array([t]))
    return {"x": f.position[0], "x_dot": f.velocity[0], "x_ddot": f.acceleration[0],
            "x_dddot": f.jerk[0], "x_ddddot": f.snap[0], "yaw": float(f.yaw[0]),
            "yaw_dot": float(f.yaw_rate[0]), "yaw_ddot": float(f.yaw_acceleration[0])}


def fly(rp: dict[str, Any], params: dict[str, Any], flown: str, duration: float,
        trajectory: Any = None) -> TruthRecord:
    """Fly RotorPy's vehicle and controller along ``trajectory`` (a mavsysid `Trajectory`;
    None: the excitation figure ``duration`` s long), sampled at `RATE_HZ`, from hover at
    its start."""
    if trajectory is None:
        trajectory = excitation_trajectory(ExcitationSpec(duration=duration))
    duration = float(trajectory.duration)
    start = _flat(trajectory, 0.0)
    n_h = hover_speed(params)
    yaw = start["yaw"]
    state = {"x": np.array(start["x"], float), "v": np.zeros(3),
             "q": np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]),
             "w": np.zeros(3), "wind": np.zeros(3), "rotor_speeds": np.full(4, n_h)}
    vehicle = rp["Multirotor"](params, initial_state=copy.deepcopy(state))
    controller = rp["SE3Control"](params)
    wind = np.zeros(3)
    if flown == "wind":
        w = HIDDEN["wind"][1]  # type: ignore[index]
        wind = np.array([w["x"], w["y"], 0.0])
    k_eta0, rate = params["k_eta"], 0.0
    if flown == "thrust_loss":
        rate = HIDDEN["thrust_loss"][1]["rate"]  # type: ignore[index]
    dt = 1.0 / RATE_HZ
    steps = round(duration * RATE_HZ)
    t = np.arange(steps + 1) * dt
    pos, quat = np.empty((steps + 1, 3)), np.empty((steps + 1, 4))
    speeds, commands = np.empty((steps + 1, 4)), np.empty((steps + 1, 4))
    imu = rp["Imu"](sampling_rate=RATE_HZ)  # true readings; `measured_imu` adds the sensor's
    gyro, accel = np.empty((steps + 1, 3)), np.empty((steps + 1, 3))
    for i in range(steps + 1):
        state["wind"] = wind
        control = controller.update(t[i], state, _flat(trajectory, t[i]))
        cmd = np.clip(control["cmd_motor_speeds"], params["rotor_speed_min"],
                      params["rotor_speed_max"])
        pos[i], speeds[i], commands[i] = state["x"], state["rotor_speeds"], cmd
        x, y, z, w = state["q"]
        quat[i] = (w, x, y, z)
        vehicle.k_eta = k_eta0 * (1.0 + rate * t[i])
        reading = imu.measurement(state, vehicle.statedot(state, control, dt), with_noise=False)
        gyro[i], accel[i] = reading["gyro"], reading["accel"]
        if i < steps:
            state = vehicle.step(state, control, dt)
    return TruthRecord(t, pos, quat, speeds, commands, gyro, accel)


def _quat_wxyz(q_xyzw: np.ndarray) -> np.ndarray:
    return np.concatenate([q_xyzw[..., 3:], q_xyzw[..., :3]], axis=-1)


def measured(rp: dict[str, Any], record: TruthRecord, variant: str, seed: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The logged position, attitude [w, x, y, z] and rotor speeds of ``variant``.

    RotorPy's motion capture adds the noise (noise density σ / √(rate / 2)); its draws
    come from numpy's global generator, seeded here per variant. The IMU's are
    `measured_imu`'s.
    """
    np.random.seed(seed)  # noqa: NPY002 - RotorPy draws from the global generator
    density = lambda s: np.full(3, s / math.sqrt(RATE_HZ / 2.0))  # noqa: E731
    mocap = rp["MotionCapture"](RATE_HZ, {
        "pos_noise_density": density(POSITION_SIGMA), "vel_noise_density": np.zeros(3),
        "att_noise_density": density(ATTITUDE_SIGMA), "rate_noise_density": np.zeros(3),
        "vel_artifact_max": 0.0, "vel_artifact_prob": 0.0, "rate_artifact_max": 0.0,
        "rate_artifact_prob": 0.0})
    p, q = record.position.copy(), record.quaternion
    if variant == "marker_offset":
        from scipy.spatial.transform import Rotation

        m = HIDDEN["marker_offset"][1]  # type: ignore[index]
        r = np.array([m["x"], m["y"], m["z"]])
        p = p + Rotation.from_quat(_xyzw(q)).apply(r)
    if variant == "pose_delay":
        shift = round(HIDDEN["pose_delay"][1]["delay"] * RATE_HZ)  # type: ignore[index]
        p = np.concatenate([np.repeat(p[:1], shift, 0), p[:-shift]])
        q = np.concatenate([np.repeat(q[:1], shift, 0), q[:-shift]])
    pm, qm = np.empty_like(p), np.empty_like(q)
    for i in range(len(p)):
        out = mocap.measurement({"x": p[i], "v": np.zeros(3), "q": _xyzw(q[i]),
                                 "w": np.zeros(3)}, with_noise=True)
        pm[i], qm[i] = out["x"], _quat_wxyz(out["q"])
    qm *= np.sign(qm[:, :1] + (qm[:, :1] == 0))  # scalar part ≥ 0
    n = record.commands if variant == "motor_lag" else record.rotor_speeds
    return pm, qm, n


def measured_imu(record: TruthRecord, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The logged gyro (rad/s) and specific force (m/s²), body FLU, shape (S, 3) each.

    RotorPy's true readings plus, per axis, a constant bias drawn once (σ
    `GYRO_BIAS_SIGMA`, `ACCEL_BIAS_SIGMA`) and white noise (σ `GYRO_SIGMA`,
    `ACCEL_SIGMA` per sample), from a generator seeded with ``seed``. The IMU keeps the
    flight's time whatever the variant does to the pose (a delayed pose leaves the IMU on
    time, as an autopilot logs it).
    """
    rng = np.random.default_rng(seed)
    n = len(record.t)
    gyro = (record.gyro + rng.normal(0.0, GYRO_BIAS_SIGMA, 3)
            + rng.normal(0.0, GYRO_SIGMA, (n, 3)))
    accel = (record.accel + rng.normal(0.0, ACCEL_BIAS_SIGMA, 3)
             + rng.normal(0.0, ACCEL_SIGMA, (n, 3)))
    return gyro, accel


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    return np.concatenate([q_wxyz[..., 1:], q_wxyz[..., :1]], axis=-1)


def fly_all(out: Path, variants: tuple[str, ...], duration: float, seed: int,
            prior_error: float = 0.3, imu: bool = True) -> dict[str, Path]:
    """Fly and log every variant (a pose log already there is kept); their directories.

    Each holds ``pose.csv``, ``vehicle.toml`` (the paper's model, the prior drawn ±
    ``prior_error`` around the reference, seeded; with ``imu`` the IMU's columns too),
    ``vehicle_declared.toml`` (the same with
    RotorPy's rotor drag law declared, its k and k_z off by c_D's prior factor) and
    ``reference.json``.
    """
    rp = import_rotorpy()
    base = rp["params"]
    rng = np.random.default_rng(seed)
    reference = reference_theta(params_for(base, "clean"))
    prior = reference * (1.0 + rng.uniform(-prior_error, prior_error, 6))
    records: dict[str, TruthRecord] = {}
    dirs = {}
    for variant in variants:
        directory = out / f"{variant}-{seed}"
        dirs[variant] = directory
        flown = _FLOWN[variant]
        params = params_for(base, flown)
        if not (directory / "pose.csv").is_file():
            if flown not in records:
                print(f"flying RotorPy: {flown} ({duration:g} s)", file=sys.stderr,
                      flush=True)
                records[flown] = fly(rp, params, flown, duration)
            p, q, n = measured(rp, records[flown], variant,
                               1000 * seed + VARIANTS.index(variant))
            directory.mkdir(parents=True, exist_ok=True)
            with PoseLogWriter(directory / "pose.csv", n.shape[1], overwrite=True,
                               imu=imu) as writer:
                if imu:
                    gyro, accel = measured_imu(records[flown],
                                               1000 * seed + VARIANTS.index(variant) + 500)
                    writer.write_rows(records[flown].t, p, q, n, gyro=gyro, accel=accel)
                else:
                    writer.write_rows(records[flown].t, p, q, n)
        factor = prior[1] / reference[1]
        name = f"rotorpy_crazyflie_{variant}"
        (directory / "vehicle.toml").write_text(vehicle_toml(params, prior, name))
        (directory / "vehicle_declared.toml").write_text(vehicle_toml(
            params, prior, name, (factor * params["k_d"], factor * params["k_z"])))
        hidden = HIDDEN[variant]
        (directory / "reference.json").write_text(json.dumps({
            "theta": reference.tolist(), "prior": prior.tolist(),
            "hidden": None if hidden is None else {"name": hidden[0], "parameters": hidden[1]},
            "variant": variant, "seed": seed, "duration": duration, "k_d": params["k_d"],
            "k_z": params["k_z"], "hover_speed": hover_speed(params), "imu": imu},
            indent=1))
    return dirs


def _stage(prefix: str, progress: bool) -> Any:
    from mavsysid.estimation.progress import StageLog, stage_listener

    return stage_listener(StageLog(prefix, sys.stderr) if progress else None)


def _scored(value: np.ndarray, sigma: np.ndarray,
            effects: dict[str, tuple[np.ndarray, np.ndarray]], ref: dict[str, Any]
            ) -> dict[str, Any]:
    """θ's error and z against the reference; c_D as its hover equivalent beside a fitted
    ``rotor_drag_linear``: c_D + k / (c_T n_h), σ² = σ_cD² + (σ_k / (c_T n_h))² (their
    correlation, strongly negative, left out: the σ is an upper bound)."""
    value, sigma = np.array(value, float), np.array(sigma, float)
    if "rotor_drag_linear" in effects:
        (k, _), (sk, _) = effects["rotor_drag_linear"]
        unit = value[0] * ref["hover_speed"]
        value[1] += k / unit
        sigma[1] = np.hypot(sigma[1], sk / unit)
    theta = np.array(ref["theta"])
    return {"value": value.tolist(), "sigma": sigma.tolist(),
            "error": (value / theta - 1.0).tolist(), "z": ((value - theta) / sigma).tolist()}


def _estimate(log: Path, vehicle: Path, ref: dict[str, Any], auto: bool, progress: bool,
              out: Path | None) -> dict[str, Any]:
    """`run_estimate` (``mavsysid estimate``) or, with ``auto``, ``--auto-effects``."""
    from mavsysid.estimation.report.text import write_estimate_json
    from mavsysid.pipeline.auto_effects import run_estimate_with_named_effects
    from mavsysid.pipeline.estimate import run_estimate

    from mavsysid.errors import JobFailedError

    t0 = time.perf_counter()
    with _stage(f"{'auto' if auto else 'estimate'} {ref['variant']}", progress):
        try:
            run = (run_estimate_with_named_effects if auto else run_estimate)(log, vehicle)
        except JobFailedError as error:
            return {"refusal": str(error), "time": time.perf_counter() - t0}
    if out is not None:
        write_estimate_json(out, run.result, run.config, log)
    result = run.result
    effects = {fe.name: (fe.value, fe.sigma) for fe in result.effects}
    row = _scored(result.final.theta.value, result.final.theta.sigma, effects, ref)
    row.update(refusal=None, time=time.perf_counter() - t0,
               effects={k: (v.tolist(), s.tolist()) for k, (v, s) in effects.items()})
    return row


def _diagnose(log: Path, vehicle: Path, estimate: Path | None, ref: dict[str, Any],
              progress: bool) -> dict[str, Any]:
    """`run_diagnose` (``mavsysid diagnose [--estimate]``): named effects, refit θ."""
    from mavsysid.pipeline.diagnose import run_diagnose

    from mavsysid.errors import JobFailedError

    t0 = time.perf_counter()
    with _stage(f"diagnose {ref['variant']}", progress):
        try:
            d = run_diagnose(log, vehicle, estimate).diagnosis
        except JobFailedError as error:
            return {"refusal": str(error), "time": time.perf_counter() - t0}
    effects = {e.name: (e.values, np.zeros(len(e.values))) for e in d.augmented_effects}
    effects.update({f.effect.name: (f.effect.values, f.sigma) for f in d.effects})
    sigma = d.theta_after_sigma if d.theta_after_sigma is not None else np.full(6, np.nan)
    row = _scored(d.theta_after, sigma, effects, ref)
    hidden = ref["hidden"]
    covered = None
    if hidden is not None and hidden["name"] in effects:
        fitted = next(f for f in d.effects if f.effect.name == hidden["name"])
        truth = np.array([hidden["parameters"].get(p, 0.0)
                          for p in fitted.effect.parameter_names()])
        covered = bool(np.all((fitted.ci95[:, 0] <= truth) & (truth <= fitted.ci95[:, 1])))
    row.update(refusal=None, time=time.perf_counter() - t0,
               named=[f.effect.name for f in d.effects],
               values={k: v.tolist() for k, (v, _) in effects.items()}, covered=covered,
               shrink=d.gap.shrink, notes=list(d.notes))
    return row


def evaluate(directory: Path, vehicle: str = "vehicle.toml", auto: bool = True,
             progress: bool = True, estimate: bool | str = True, diagnose: bool = True
             ) -> dict[str, Any]:
    """``estimate``, ``diagnose`` (from the estimate, or the prior if it was refused or
    ``estimate`` is False) and ``estimate --auto-effects`` on one flight: the library
    functions the CLI calls. ``estimate="reuse"`` diagnoses from the estimate an earlier
    run wrote into the flight's directory. ``diagnose`` False skips ``diagnose``.

    Returns the row of the table: θ error and z per parameter of each, the refusals, what
    was named (and whether the hidden effect's 95 % interval holds its truth), run times.
    """
    log, toml = directory / "pose.csv", directory / vehicle
    ref = json.loads((directory / "reference.json").read_text())
    out = directory / f"estimate-{Path(vehicle).stem}.json"
    row: dict[str, Any] = {"variant": ref["variant"], "seed": ref["seed"], "vehicle": vehicle,
                           "hidden": ref["hidden"]["name"] if ref["hidden"] else None}
    if estimate != "reuse":
        out.unlink(missing_ok=True)
    row["estimate"] = (_estimate(log, toml, ref, False, progress, out) if estimate is True
                       else None)
    row["diagnose"] = (_diagnose(log, toml, out if out.is_file() else None, ref, progress)
                       if diagnose else None)
    row["auto"] = _estimate(log, toml, ref, True, progress, None) if auto else None
    return row


def _theta_cells(part: dict[str, Any] | None) -> str:
    from mavsysid.vehicle.config import PARAMETER_NAMES

    if part is None:
        return "—"
    if part.get("refusal"):
        return "refused: " + part["refusal"]
    return " ".join(f"{n} {100 * e:+.2f}% ({z:+.1f}σ)" for n, e, z in
                    zip(PARAMETER_NAMES, part["error"], part["z"], strict=True))


def format_row(row: dict[str, Any]) -> str:
    """The flight's lines of the table: estimate, diagnose, estimate --auto-effects."""
    d = row["diagnose"]
    lines = [f"{row['variant']} (hidden: {row['hidden']}), {row['vehicle']}"]
    if row["estimate"] is not None:
        lines.append(f"  estimate          {row['estimate']['time']:6.1f} s  "
                     + _theta_cells(row["estimate"]))
    if d is not None:
        named = ("refused: " + d["refusal"] if d.get("refusal")
                 else ", ".join(d["named"]) or "nothing")
        if d.get("covered") is not None:
            named += f" (hidden effect's CI holds its truth: {d['covered']})"
        lines += [f"  diagnose          {d['time']:6.1f} s  named {named}",
                  "  θ with the named  " + " " * 9
                  + _theta_cells(None if d.get("refusal") else d)]
    if row["auto"] is not None:
        lines.append(f"  --auto-effects    {row['auto']['time']:6.1f} s  "
                     + _theta_cells(row["auto"]))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--duration", type=float, default=50.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--fly-only", action="store_true")
    parser.add_argument("--declared", action="store_true",
                        help="use the vehicle file that declares RotorPy's rotor drag law")
    parser.add_argument("--no-auto", action="store_true", help="skip --auto-effects")
    parser.add_argument("--no-diagnose", action="store_true", help="skip diagnose")
    parser.add_argument("--no-estimate", action="store_true",
                        help="diagnose from the vehicle file's θ (no estimate first)")
    parser.add_argument("--reuse-estimate", action="store_true",
                        help="diagnose from the estimate an earlier run wrote")
    parser.add_argument("--quiet", action="store_true", help="no stage messages")
    parser.add_argument("--json", type=Path, help="write the rows as JSON")
    parser.add_argument("--no-imu", action="store_true",
                        help="write pose.csv without the IMU's columns")
    args = parser.parse_args()
    dirs = fly_all(args.out, tuple(args.variants.split(",")), args.duration, args.seed,
                   imu=not args.no_imu)
    if args.fly_only:
        return
    vehicle = "vehicle_declared.toml" if args.declared else "vehicle.toml"
    rows = []
    for directory in dirs.values():
        estimate = "reuse" if args.reuse_estimate else not args.no_estimate
        rows.append(evaluate(directory, vehicle, not args.no_auto, not args.quiet, estimate,
                             not args.no_diagnose))
        print(format_row(rows[-1]), flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
