"""The one validator of a planning request, used by ``mavsysid plan`` and by the planner.

`check_request` refuses, before any planning time is spent, a request that cannot make
sense: a malformed budget, sample count, planning time, seed or refinement setting; a box
too small for the vehicle or a start too close to its walls; limits within which the
vehicle cannot hover; a rotor headroom without the hover speed. Each refusal is one line
naming the option (``--budget``, ``--box``, …) or the configuration key at fault.
"""

from __future__ import annotations

import math

import numpy as np
from mavsysid.planner.feasibility import check_rotor_headroom, check_vertex_state
from mavsysid.planner.kinematic_check import check_limits
from mavsysid.planner.results import PlannerSettings
from mavsysid.planner.segments import VertexState
from mavsysid.vehicle.config import GRAVITY, VehicleConfig
from mavsysid.vehicle.thrust_envelope import thrust_envelope

from mavsysid.errors import ConfigError, InputError, JobFailedError

__all__ = ["MIN_BOX_SIDE", "check_request", "rotor_clearance"]

#: Shortest side of a flight box, m, whatever the vehicle.
MIN_BOX_SIDE = 0.5


def rotor_clearance(config: VehicleConfig) -> float:
    """Distance from the centre of gravity to the farthest rotor hub in the x-y plane, m."""
    return float(np.max(np.linalg.norm(config.rotor_positions[:, :2], axis=1)))


def _check_box(settings: PlannerSettings, config: VehicleConfig) -> None:
    """Refuse a malformed or too small box, or a start whose rotors would leave it."""
    box = np.asarray(settings.box, dtype=float)
    shown = ",".join(f"{v:g}" for v in box)
    if box.shape != (6,) or not np.all(np.isfinite(box)):
        raise InputError(f"--box {shown}: expected 6 finite numbers "
                         "x_min,y_min,z_min,x_max,y_max,z_max")
    side = box[3:] - box[:3]
    clearance = rotor_clearance(config)
    need = max(MIN_BOX_SIDE, 2.0 * clearance)
    for axis, length in zip("xyz", side, strict=True):
        if length <= 0.0:
            raise InputError(f"--box {shown}: {axis}_min must be below {axis}_max")
        if length < need:
            raise InputError(f"--box {shown}: the {axis} side is {length:g} m; the "
                             f"{config.name} needs at least {need:.2g} m")
    start = settings.start_pose
    if start.shape != (4,) or not np.all(np.isfinite(start)):
        raise InputError("--start: expected 4 finite numbers x,y,z,yaw")
    # The start hover must leave the rotors inside the box, not only the centre of gravity.
    margin = float(np.min(np.concatenate([start[:3] - box[:3], box[3:] - start[:3]])))
    if margin < clearance:
        raise InputError(
            f"--start {','.join(f'{v:g}' for v in start)}: the {config.name} must start at "
            f"least {clearance:.2g} m inside --box {shown}, got {margin:.2g} m")


def _check_hover(config: VehicleConfig) -> None:
    """Refuse limits within which the vehicle cannot hover (one line naming the key).

    Both thrust comparisons are strict: a vehicle whose least thrust equals its weight
    cannot descend from hover, one whose greatest thrust equals it has no margin to climb
    or to correct a disturbance.
    """
    limits = config.limits
    if limits.thrust_min_ratio >= 1.0:
        raise ConfigError(
            f"{config.source}: [limits].thrust_min_ratio: below 1 so that the vehicle can "
            f"hover (T_min < m g), got {limits.thrust_min_ratio!r}")
    if limits.thrust_max_ratio <= 1.0:
        raise ConfigError(
            f"{config.source}: [limits].thrust_max_ratio: above 1 so that the vehicle can "
            f"climb out of hover (T_max > m g), got {limits.thrust_max_ratio!r}")
    idle = thrust_envelope(config).rotor_min  # all rotors at rotor_speed_min, per mass
    if idle >= GRAVITY:
        raise ConfigError(
            f"{config.source}: [limits].rotor_speed_min: a speed at which the rotors lift "
            f"less than m g = {config.mass * GRAVITY:.4g} N, got {limits.rotor_speed_min!r} "
            f"rad/s giving {idle * config.mass:.4g} N")


def _check_numbers(settings: PlannerSettings) -> None:
    """Refuse a budget, sample count, planning time, seed or refinement out of range."""
    if not (math.isfinite(settings.budget) and settings.budget > 0.0):
        raise InputError(f"--budget {settings.budget:g}: expected a flight time > 0 s")
    if settings.max_samples is not None and settings.max_samples < 1:
        raise InputError(f"--samples {settings.max_samples}: expected at least 1 sample")
    if not settings.planning_time > 0.0:
        raise InputError(f"--time {settings.planning_time:g}: expected a planning time > 0 s "
                         "(or --samples N to stop after N samples)")
    if math.isinf(settings.planning_time) and settings.max_samples is None:
        raise InputError("--time: an unlimited planning time needs --samples N")
    if settings.seed < 0:
        raise InputError(f"--seed {settings.seed}: expected an integer ≥ 0")
    if settings.refine_steps < 0:
        raise InputError(f"--refine-steps {settings.refine_steps}: expected an integer ≥ 0")
    if not 0.0 <= settings.refine_share < 1.0 or settings.refine_split < 1:
        raise InputError(f"refinement: share {settings.refine_share:g} must lie in [0, 1) "
                         f"and split {settings.refine_split} must be ≥ 1")
    if not (settings.measurement_rate > 0.0 and settings.prior_relative_sigma > 0.0):
        raise InputError("planner settings: measurement rate and prior σ must be positive")
    if not 0.0 <= settings.rotor_confidence <= 6.0:
        raise InputError(f"--rotor-confidence {settings.rotor_confidence:g}: expected a "
                         "normal quantile in [0, 6]")
    _check_prior_covariance(settings)


def _check_prior_covariance(settings: PlannerSettings) -> None:
    """Refuse a prior covariance that is not a finite, symmetric, positive definite 6 × 6."""
    if settings.prior_covariance is None:
        return
    try:
        cov = settings.theta_covariance
    except ValueError:
        raise InputError("prior covariance: expected 6 × 6 numbers") from None
    if not (np.all(np.isfinite(cov)) and np.allclose(cov, cov.T, rtol=1e-9, atol=0.0)
            and np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() > 0.0):
        raise InputError("prior covariance: expected a finite, symmetric, positive definite "
                         "6 × 6 matrix of relative θ errors")


def _check_hover_chance(config: VehicleConfig, settings: PlannerSettings) -> None:
    """Refuse a request whose start hover already fails the chance-constrained rotor check:
    with that prior spread no flight is safe until an opening flight narrows it."""
    if not settings.rotor_check or settings.rotor_confidence == 0.0:
        return
    pose = settings.start_pose
    if not check_vertex_state(VertexState.hover(pose[:3], float(pose[3])), config,
                              np.asarray(settings.box, dtype=float),
                              rotor_headroom=settings.rotor_headroom,
                              theta_covariance=settings.theta_covariance,
                              rotor_confidence=settings.rotor_confidence):
        raise JobFailedError(
            f"--rotor-confidence {settings.rotor_confidence:g}: with the prior's spread even "
            "the start hover may need more than the rotors' range; narrow the prior with a "
            "gentle opening flight (estimate it first) or lower the confidence")


def check_request(config: VehicleConfig, settings: PlannerSettings) -> None:
    """Refuse a planning request that cannot make sense, before planning starts.

    Parameters
    ----------
    config : VehicleConfig
        The vehicle to plan for (rotor positions, mass, θ and `Limits`).
    settings : PlannerSettings
        The request.

    Raises
    ------
    InputError
        A budget or planning time ≤ 0, no limit on planning at all, a sample count ≤ 0,
        a negative seed or refinement step count, a refinement share outside [0, 1) or
        split < 1, a malformed or too small box, a start closer to a wall than the
        rotors reach, a rotor headroom outside [0, 0.5) or without the hover speed, or an
        autopilot limit that is not > 0;
        or (`ConfigError`) limits the vehicle cannot hover within. One line each.
    """
    _check_numbers(settings)
    _check_box(settings, config)
    _check_hover(config)
    check_rotor_headroom(config, settings.rotor_headroom, "--rotor-headroom")
    _check_hover_chance(config, settings)
    if settings.autopilot_limits is not None:
        check_limits(settings.autopilot_limits)
