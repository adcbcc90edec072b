"""The chance-constrained rotor check: its first-order spread and what it guarantees."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.planner.feasibility import check_segment, segment_slack
from mavsysid.planner.sample_slacks import slab_spread
from mavsysid.planner.search_setup import initial_covariance, search_model
from mavsysid.planner.segments import Segment, VertexState, connect_fixed
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.allocation import allocation_pinv
from mavsysid.vehicle.config import SHIPPED_VEHICLES, VehicleConfig, load_vehicle
from mavsysid.vehicle.flatness import SAMPLE_SIZE, flat_sample
from mavsysid.vehicle.linearization import E_THETA

BOX = np.array([-20.0, -20.0, -20.0, 20.0, 20.0, 20.0])
#: θ indices of (c_T, c_M, j_x, j_y, j_z), the order of the spread matrix.
WRENCH_THETA = [0, 2, 3, 4, 5]


def rotor_config(name: str) -> VehicleConfig:
    """A shipped vehicle whose other dynamic limits never decide, so the rotors do."""
    base = load_vehicle(name)
    return replace(base, limits=replace(
        base.limits, body_rate_max=100.0, yaw_acceleration_max=1e3, speed_max=100.0,
        thrust_min_ratio=0.01, thrust_max_ratio=10.0))


def wrench_sample(rng: np.random.Generator, J: np.ndarray) -> tuple[np.ndarray, float]:
    """One flatness sample (rates, rate derivatives, torque) with random derivatives and
    its specific thrust norm."""
    a, jerk, snap = rng.normal(size=(3, 3)) * [[3.0], [10.0], [60.0]]
    yaw = rng.normal(size=3) * [1.0, 2.0, 10.0]
    sample = np.empty(SAMPLE_SIZE)
    assert flat_sample(*a, *jerk, *snap, *yaw, J, sample)
    return sample, float(sample[0])


def rotor_squares(cfg: VehicleConfig, theta: np.ndarray, sample: np.ndarray,
                  thrust: float) -> np.ndarray:
    """n² = A⁺(θ) w(θ), written out from the allocation and Euler's equation at θ."""
    rate, rate_dot = sample[10:13], sample[13:16]
    J = theta[3:6]
    torque = J * rate_dot + np.cross(rate, J * rate)
    return allocation_pinv(cfg, theta) @ np.concatenate([[thrust], torque])


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
@pytest.mark.parametrize("seed", [0, 1])
def test_spread_is_the_first_order_spread_of_n_squared(name: str, seed: int) -> None:
    """slab_spread equals √(gᵀΣg) with g the finite-difference gradient of A⁺(θ) w(θ)."""
    cfg = load_vehicle(name)
    rng = np.random.default_rng([seed, 77])
    theta = cfg.theta
    sample, norm = wrench_sample(rng, theta[3:6])
    thrust = cfg.mass * norm
    normals = allocation_pinv(cfg, theta)
    root = rng.normal(size=(5, 5)) * 0.1
    spread = root @ root.T
    h = 1e-6
    for i in range(normals.shape[0]):
        grad = np.empty(5)
        for k, j in enumerate(WRENCH_THETA):
            up, down = theta.copy(), theta.copy()
            up[j] *= 1 + h
            down[j] *= 1 - h
            grad[k] = (rotor_squares(cfg, up, sample, thrust)[i]
                       - rotor_squares(cfg, down, sample, thrust)[i]) / (2 * h)
        expected = np.sqrt(grad @ spread @ grad)
        got = slab_spread(np.ascontiguousarray(normals[i]), thrust, sample[16:19], sample,
                          theta[3:6].copy(), spread)
        assert got == pytest.approx(expected, rel=1e-5, abs=1e-9 * np.abs(normals[i]).max())


def scaled_segment(shape: tuple[np.ndarray, ...], scale: float) -> Segment:
    """A 1 s fixed-end segment between two flat states of the given shape times ``scale``."""
    p0, y0, p1, y1 = shape
    return connect_fixed(VertexState(p0 * scale, y0 * scale),
                         VertexState(p1 * scale, y1 * scale), 1.0)


def boundary_scale(cfg: VehicleConfig, shape: tuple[np.ndarray, ...]) -> float:
    """The scale, to 1 %, at which the plain check starts refusing the segment's shape."""
    lo, hi = 1e-3, 10.0
    while hi / lo > 1.01:
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if check_segment(scaled_segment(shape, mid), cfg, BOX) else (lo, mid)
    return lo


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_chance_accepted_segments_hold_for_theta_within_the_spread(name: str) -> None:
    """Near the rotor limit: a segment accepted at z = 3 with σ = 4 % on one parameter stays
    feasible with it 2.5 σ off either way, and never one the plain check refuses; some
    segments the plain check accepts are refused (the chance margin bites)."""
    cfg = rotor_config(name)
    rng = np.random.default_rng(5)
    sigma = 0.04
    refused_only_by_chance = accepted = 0
    for trial in range(10):
        weights = np.array([1.0, 3.0, 10.0, 40.0, 150.0])[:, None]
        shape = (rng.normal(size=(5, 3)) * weights, rng.normal(size=3) * [1.0, 6.0, 40.0],
                 rng.normal(size=(5, 3)) * weights, rng.normal(size=3) * [1.0, 6.0, 40.0])
        edge = boundary_scale(cfg, shape)
        for k in range(5):
            cov = np.zeros((6, 6))
            cov[WRENCH_THETA[k], WRENCH_THETA[k]] = sigma**2
            for fraction in (0.5, 0.8, 0.95, 0.99):
                segment = scaled_segment(shape, fraction * edge)
                plain = check_segment(segment, cfg, BOX).feasible
                chance = check_segment(segment, cfg, BOX, theta_covariance=cov,
                                       rotor_confidence=3.0).feasible
                assert not chance or plain
                refused_only_by_chance += plain and not chance
                accepted += chance
                if not chance:
                    continue
                for sign in (-1.0, 1.0):
                    theta = cfg.theta.copy()
                    theta[WRENCH_THETA[k]] *= 1 + sign * 2.5 * sigma
                    assert check_segment(segment, cfg, BOX, theta=theta).feasible, (trial, k)
    assert refused_only_by_chance > 0 and accepted > 0


def test_prior_covariance_sets_the_planners_initial_theta_belief() -> None:
    """PlannerSettings.prior_covariance (relative, correlated) is the initial θ block."""
    cfg = load_vehicle("quad_x")
    root = np.random.default_rng(3).normal(size=(6, 6)) * 0.05
    cov = root @ root.T
    settings = PlannerSettings(prior_covariance=tuple(map(tuple, cov)))
    sigma = initial_covariance(search_model(cfg, settings), cfg, settings)
    np.testing.assert_array_equal(sigma[E_THETA, E_THETA], cov)
    default = PlannerSettings(prior_relative_sigma=0.3)
    np.testing.assert_allclose(default.theta_covariance, np.eye(6) * 0.09)


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_segment_slack_is_negative_inside_the_limits_and_positive_beyond(name: str) -> None:
    """segment_slack < 0 on segments the check accepts, > 0 well past the rotor limit, and
    rises as the segment is scaled up."""
    cfg = rotor_config(name)
    rng = np.random.default_rng(11)
    weights = np.array([1.0, 3.0, 10.0, 40.0, 150.0])[:, None]
    shape = (rng.normal(size=(5, 3)) * weights, rng.normal(size=3) * [1.0, 6.0, 40.0],
             rng.normal(size=(5, 3)) * weights, rng.normal(size=3) * [1.0, 6.0, 40.0])
    edge = boundary_scale(cfg, shape)
    slacks = [segment_slack(scaled_segment(shape, f * edge), cfg, grid_step=0.001)
              for f in (0.3, 0.6, 0.9, 1.5)]
    assert max(slacks[:3]) < 0.0 < slacks[3]
    assert slacks[0] < slacks[1] < slacks[2]
