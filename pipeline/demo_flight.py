"""The demo's flight: the hidden truth, the planning envelope and the MAVLink flight.

The simulated vehicle's true θ differs from the nominal by a seeded, hidden factor
(`hidden_scale`); the demo plans inside a reduced envelope (`with_headroom`), flies the
plan over MAVLink on UDP loopback against ``mavsysid sim`` in its own process
(`SimVehicleProcess`, `fly_over_mavlink`) and keeps the part of the recording where the
plan was flown (`trajectory_window`). `mavsysid.pipeline.demo` strings the rounds
together.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from mavsysid.estimation import (
    FlightData,
    load_flight,
)
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.trajectory_file import read_trajectory
from mavsysid.pipeline.stream import run_stream
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import JobFailedError

__all__ = [
    "ENVELOPE",
    "HIDDEN_SPREAD",
    "ROTOR_HEADROOM",
    "SIM_START_TIMEOUT",
    "TELEMETRY_RATE",
    "SimVehicleProcess",
    "fly_over_mavlink",
    "hidden_scale",
    "trajectory_window",
    "with_headroom",
]

#: Largest hidden deviation of the simulated vehicle's θ from the nominal, relative, per
#: parameter. c_T stays close: the simulated autopilot, like a real one without hover
#: throttle learning, holds altitude with the nominal c_T and has no integral action.
HIDDEN_SPREAD = np.array([0.05, 0.3, 0.3, 0.3, 0.3, 0.3])


#: Share of the top rotor speed the plans leave to the autopilot's feedback: the vehicle's
#: true θ is not the model's, and a plan at the model's rotor limit saturates the real one.
ROTOR_HEADROOM = 0.15
#: Share of the body-rate, yaw-acceleration and thrust envelope the demo plans in: room
#: for an autopilot that follows 50 Hz setpoints with a wrong model.
ENVELOPE = 0.7

#: Pose and rotor-speed telemetry rate asked of the vehicle, Hz. The EKF takes rotor speeds
#: as linear between samples; the autopilot's speeds change with every 50 Hz setpoint, and
#: at 100 Hz that already biased c_D by 5σ (1σ at 200 Hz, on the same flight). 250 Hz is
#: a whole number of the simulated autopilot's 2 ms ticks, so the samples are uniform.
TELEMETRY_RATE = 250.0


def hidden_scale(config: VehicleConfig, seed: int) -> np.ndarray:
    """True θ / nominal θ of the simulated vehicle: seeded, within ±`HIDDEN_SPREAD`, and
    drawn again until the true inertia is as physical as the nominal one (a true θ must
    pass the same config checks, since plans carry the updated model).

    Parameters
    ----------
    config : VehicleConfig
        The nominal vehicle.
    seed : int
        Seed of the draw.
    """
    rng = np.random.default_rng([seed, 7])
    j = config.theta[3:]
    slack = max(1.0, float(np.max(j / (j.sum() - j))))
    while True:
        scale = 1.0 + rng.uniform(-HIDDEN_SPREAD, HIDDEN_SPREAD)
        jt = j * scale[3:]
        if np.all(jt <= slack * (jt.sum() - jt)):
            return scale


class SimVehicleProcess:
    """``mavsysid sim`` in its own process, sending to a loopback port.

    Parameters
    ----------
    directory : Path
        Receives the process's output (``sim.out``) and its truth log (``truth/``).
    vehicle : str
        Shipped vehicle name or TOML path: the nominal model.
    scale : ndarray, shape (6,)
        True θ / nominal θ (`hidden_scale`).
    port : int
        UDP loopback port the vehicle sends to.
    speedup : float
        Simulated time per wall second.
    seed : int
        Seed of the simulator's noise.
    hidden : sequence of str
        Effects the vehicle has and the model does not (``NAME:KEY=VALUE,…``).
    """

    def __init__(self, directory: Path, vehicle: str, scale: np.ndarray, port: int,
                 speedup: float, seed: int, hidden: Sequence[str] = ()) -> None:
        self.directory = directory
        directory.mkdir(parents=True, exist_ok=True)
        self._out = open(directory / "sim.out", "wb")  # noqa: SIM115 - the child writes it
        args = ["sim", "--connect", f"udpout:127.0.0.1:{port}", "--vehicle", vehicle,
                "--speedup", f"{speedup:g}", "--lockstep", "--seed", str(seed), "--truth-log",
                str(directory / "truth"), "--theta-scale", ",".join(f"{v:.12g}" for v in scale)]
        for text in hidden:
            args += ["--hidden-effect", text]
        self.process = subprocess.Popen([sys.executable, "-m", "mavsysid", *args],
                                        stdout=self._out, stderr=subprocess.STDOUT)

    def stop(self) -> None:
        """Interrupt the vehicle (killed if it does not end within 15 s) and close its output."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        self._out.close()


#: How long the streamer waits for the simulated vehicle's first heartbeat, s: on a cold
#: cache the vehicle compiles its kernels first, minutes on a busy two-core machine.
SIM_START_TIMEOUT = 600.0


def with_headroom(model: VehicleConfig) -> VehicleConfig:
    """The model the demo plans with: `ROTOR_HEADROOM` off its top rotor speed, and its
    body rate, yaw acceleration and thrust above hover scaled to `ENVELOPE`.

    Parameters
    ----------
    model : VehicleConfig
        The current model.
    """
    lim = model.limits
    return replace(model, limits=replace(
        lim, rotor_speed_max=(1.0 - ROTOR_HEADROOM) * lim.rotor_speed_max,
        body_rate_max=ENVELOPE * lim.body_rate_max,
        yaw_acceleration_max=ENVELOPE * lim.yaw_acceleration_max,
        thrust_max_ratio=1.0 + ENVELOPE * (lim.thrust_max_ratio - 1.0)))


def trajectory_window(flight_dir: Path, model: VehicleConfig) -> FlightData:
    """The recorded flight while the plan was flown (the streamer's ``trajectory_window``):
    the ground, take-off and landing are not in the model and stay out of the estimate.

    Parameters
    ----------
    flight_dir : Path
        The streamed flight directory.
    model : VehicleConfig
        The vehicle the log is read for.
    """
    flight = load_flight(flight_dir / "pose.csv", model)
    window = read_meta(flight_dir / "meta.json").get("trajectory_window")
    if not window:
        raise JobFailedError(f"{flight_dir}: the flight has no trajectory window; it did not "
                             "fly the plan")
    return flight.time_slice(float(window["start"]), float(window["end"]))


def fly_over_mavlink(plan_file: Path, directory: Path, vehicle: str, scale: np.ndarray,
                     speedup: float, seed: int, hidden: Sequence[str],
                     say: Callable[[str], None], progress: bool) -> tuple[Path, float]:
    """Start the simulated vehicle, stream the plan to it, stop it.

    Parameters
    ----------
    plan_file : Path
        The trajectory file to fly.
    directory : Path
        Receives the flight directory and the simulated vehicle's ``sim/`` folder.
    vehicle, scale, speedup, seed, hidden
        Of the simulated vehicle (`SimVehicleProcess`).
    say : callable
        Receives one-line progress messages.
    progress : bool
        Show the streamer's progress bar.

    Returns
    -------
    flight_dir : Path
        The recorded flight directory (``pose.csv``, ``flight.tlog``, ``meta.json``).
    tracking_rms : float
        Position tracking RMS of the flight, m (NaN if the streamer did not report it).
    """
    port = free_udp_port()
    sim = SimVehicleProcess(directory / "sim", vehicle, scale, port, speedup, seed, hidden)
    try:
        time.sleep(0.2)
        if sim.process.poll() is not None:
            raise JobFailedError(f"the simulated vehicle did not start; see {sim.directory}")
        # Both ends are ours: lock-step, so the demo flies the same flight on a slow or
        # busy machine as on an idle one (`mavsysid.flight.simvehicle.clock`).
        # The demo is its own operator: it flies in the box it planned in.
        box = read_trajectory(plan_file).box
        stream = StreamSettings(connect=f"udp:127.0.0.1:{port}", speedup=speedup, box=box,
                                telemetry_rate=TELEMETRY_RATE, log_dir=directory,
                                lockstep=True, heartbeat_timeout=SIM_START_TIMEOUT)
        outcome = run_stream(plan_file, stream, say=say, progress=progress)
    finally:
        sim.stop()
    return outcome.directory, float(outcome.meta.get("tracking", {}).get("rms_m", np.nan))
