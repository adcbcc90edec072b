"""A simulated micro_quad flight logged the way real small vehicles are.

`realistic_micro_quad_flight` flies the built-in excitation with

* the pose from an on-board estimator (`OnboardPoseEstimate`): 20 ms latency, 15 ms
  smoothing, correlated noise 10× the config's motion-capture σ;
* a 500 Hz log with timestamp jitter, single dropped samples and burst gaps
  (`degrade_pose_log`);
* hidden motor lag, linear rotor drag and a steady wind (catalogue effects);

and `prior_config` writes a vehicle TOML whose θ is a seeded 30–50 % off the truth.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mavsysid.flight.offline.effects import hidden_effect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.log_timing import LogTiming, degrade_pose_log
from mavsysid.flight.offline.sensor_path import OnboardPoseEstimate
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import VehicleConfig, load_vehicle, vehicle_to_toml
from mavsysid.vehicle.model_effects import ModelEffect, effect_from_values

__all__ = ["REALISTIC_EFFECTS", "RealisticFlight", "onboard_pose", "prior_config",
           "realistic_effects", "realistic_micro_quad_flight"]

#: Hidden physics of the realistic flight (micro_quad scale): motor τ 30 ms (the config
#: says 15 ms); rotor drag linear in n at about half the paper's quadratic drag in hover
#: (c_T n_hover c_D ≈ 3.8e-7 N·s/m per rotor); a 1.2 m/s steady wind.
REALISTIC_EFFECTS = {
    "motor_lag": {"tau": 0.03},
    "rotor_drag_linear": {"k": 2e-7},
    "wind": {"x": 1.0, "y": 0.6},
}


@dataclass(frozen=True)
class RealisticFlight:
    """The flight directory, its pose log, the vehicle and the true θ (6,)."""

    directory: Path
    pose: Path
    config: VehicleConfig
    truth: np.ndarray
    rows_kept: int


def realistic_effects(names: tuple[str, ...] = tuple(REALISTIC_EFFECTS)) -> list[ModelEffect]:
    """The hidden catalogue effects of the realistic flight (a subset by name)."""
    return [effect_from_values(n, REALISTIC_EFFECTS[n]) for n in names]


def onboard_pose(config: VehicleConfig, seed: int, noise_factor: float = 10.0,
                 delay: float = 0.02, time_constant: float = 0.015) -> OnboardPoseEstimate:
    """An on-board estimator's pose with correlated noise ``noise_factor`` × the config's σ."""
    nz = config.noise
    return OnboardPoseEstimate(delay=delay, time_constant=time_constant,
                               position_sigma=noise_factor * nz.position_sigma,
                               attitude_sigma=noise_factor * nz.attitude_sigma,
                               correlation_time=0.2, seed=10_000 + seed)


def realistic_micro_quad_flight(
    directory: Path, seed: int = 0, duration: float = 60.0,
    effects: tuple[str, ...] = tuple(REALISTIC_EFFECTS), sensor_path: bool = True,
    timing: LogTiming | None = None, vehicle: str = "micro_quad",
) -> RealisticFlight:
    """Fly the excitation with the realistic sensor path and hidden effects; log at 500 Hz.

    Parameters
    ----------
    directory : Path
        New flight directory (``pose.csv``, ``truth.csv``, ``meta.json``).
    seed : int
        Seeds the white noise, the on-board estimator's noise and the log timing.
    duration : float
        s, of the built-in excitation (≥ 10).
    effects : tuple of str
        Names in `REALISTIC_EFFECTS` made hidden truth.
    sensor_path : bool
        False: motion-capture pose (white noise only), exact 500 Hz stamps.
    timing : LogTiming, optional
        Default: 0.2 ms jitter, 2 % single drops, three 20–150 ms gaps.
    vehicle : str
    """
    config = load_vehicle(vehicle)
    truth_effects = [hidden_effect(e) for e in realistic_effects(effects)]
    if sensor_path:
        truth_effects.append(onboard_pose(config, seed))
    settings = SimulationSettings(physics_rate=1000.0, control_rate=500.0, log_rate=500.0,
                                  seed=seed)
    trajectory = excitation_trajectory(ExcitationSpec(duration=duration))
    Simulator(config, settings=settings, effects=truth_effects).run(trajectory, directory)
    rows = None
    if sensor_path:
        timing = replace(timing or LogTiming(), seed=20_000 + seed)
        rows = degrade_pose_log(directory, timing)
    pose = Path(directory) / "pose.csv"
    if rows is None:
        rows = sum(1 for _ in pose.open()) - 1
    return RealisticFlight(Path(directory), pose, config, config.theta.copy(), rows)


def prior_config(config: VehicleConfig, path: Path, seed: int,
                 low: float = 0.3, high: float = 0.5) -> tuple[Path, np.ndarray]:
    """Write ``config`` with θ off its own by ``low``–``high`` (relative, random sign each).

    Returns the TOML path and the prior θ (6,).
    """
    rng = np.random.default_rng(30_000 + seed)
    factor = 1.0 + rng.choice([-1.0, 1.0], 6) * rng.uniform(low, high, 6)
    theta = config.theta * factor
    path = Path(path)
    path.write_text(vehicle_to_toml(config.with_parameters(theta)), encoding="utf-8")
    return path, theta
