"""The exact allocation polytope (slabs) against an independent LP, and against A⁺."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.vehicle.allocation import allocation_matrix
from mavsysid.vehicle.allocation_polytope import (
    allocation_slabs,
    pseudo_inverse_slabs,
    wrench_reachable_lp,
    zonotope_slabs,
)
from mavsysid.vehicle.config import SHIPPED_VEHICLES, ConfigError, load_vehicle
from mavsysid.vehicle.config_toml import vehicle_to_toml
from scipy.optimize import linprog

WRENCHES_PER_VEHICLE = 3400  # × 3 shipped vehicles ≥ 10⁴


def _setting(name: str) -> tuple[np.ndarray, float, float]:
    """(A, n²_min, n²_max) of a shipped vehicle, with a non-zero minimum speed."""
    cfg = load_vehicle(name)
    hi = cfg.limits.rotor_speed_max**2
    return allocation_matrix(cfg), 0.05 * hi, hi


def random_wrenches(A: np.ndarray, lo: float, hi: float, slabs, count: int,
                     rng: np.random.Generator) -> np.ndarray:
    """Half from an enlarged rotor box (in and out), half within 10⁻⁵…10⁻² of the boundary.

    Boundary points lie on rays from the centre, at (1 ± δ) times the slabs' boundary
    distance: a missing facet shows up as an LP-infeasible point just inside, a wrong
    one as an LP-feasible point just outside.
    """
    k, half = A.shape[1], count // 2
    n2 = lo + (hi - lo) * rng.uniform(-0.3, 1.3, size=(half, k))
    centre = A @ np.full(k, 0.5 * (lo + hi))
    direction = rng.normal(size=(count - half, 4)) * np.abs(A).max(axis=1) * hi
    # Largest t with centre + t d in every slab: per slab, the bound that d moves towards.
    rate = direction @ slabs.normals.T
    room = np.where(rate > 0, slabs.upper - centre @ slabs.normals.T,
                    slabs.lower - centre @ slabs.normals.T)
    t_edge = (room / np.where(rate == 0, np.inf, rate)).min(axis=1)
    delta = 10.0 ** rng.uniform(-5, -2, size=t_edge.size) * rng.choice([-1.0, 1.0], t_edge.size)
    near = centre + (t_edge * (1 + delta))[:, None] * direction
    return np.vstack([n2 @ A.T, near])


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_slabs_and_lp_agree_onrandom_wrenches(name: str) -> None:
    """Every one of 3400 seeded wrenches per vehicle (half near the boundary): same verdict."""
    A, lo, hi = _setting(name)
    slabs = zonotope_slabs(A, lo, hi)
    w = random_wrenches(A, lo, hi, slabs, WRENCHES_PER_VEHICLE, np.random.default_rng(20))
    fast = slabs.contains(w)
    lp = np.array([wrench_reachable_lp(A, lo, hi, x) for x in w])
    print(name, "agree", int((fast == lp).sum()), "of", w.shape[0], "reachable", int(lp.sum()))
    assert 0.2 * w.shape[0] < lp.sum() < 0.8 * w.shape[0]  # both verdicts well represented
    np.testing.assert_array_equal(fast, lp)


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_pseudo_inverse_set_is_inside_the_polytope_and_equal_for_quads(name: str) -> None:
    """A⁺ w in the box implies reachable; with 4 rotors A is square and the sets coincide."""
    A, lo, hi = _setting(name)
    exact, pinv = zonotope_slabs(A, lo, hi), pseudo_inverse_slabs(A, lo, hi)
    rng = np.random.default_rng(3)
    w = (lo + (hi - lo) * rng.uniform(-0.3, 1.3, size=(20000, A.shape[1]))) @ A.T
    away = np.abs(exact.slack(w)) > 1e-9  # not on the boundary to rounding
    assert not np.any(pinv.contains(w) & ~exact.contains(w))
    if A.shape[1] == 4:
        np.testing.assert_array_equal(pinv.contains(w)[away], exact.contains(w)[away])
    else:
        assert np.sum(exact.contains(w) & ~pinv.contains(w)) > 0.05 * w.shape[0]


def _max_yaw_lp(A: np.ndarray, lo: float, hi: float, thrust: float, roll: float) -> float:
    """Largest τ_z over the rotor box with the given thrust, roll and zero pitch torque."""
    result = linprog(-A[3] * 1e6, A_eq=A[:3], b_eq=[thrust, roll, 0.0],
                     bounds=(lo, hi), method="highs")
    return float(A[3] @ result.x) if result.status == 0 else -np.inf


def max_yaw_slabs(slabs, thrust: float, roll: float) -> float:
    """Largest τ_z the slabs admit along the τ_z axis (each slab bounds it linearly)."""
    base = slabs.normals @ np.array([thrust, roll, 0.0, 0.0])
    rate = slabs.normals[:, 3]
    if np.any((base > slabs.upper) | (base < slabs.lower)):
        return -np.inf
    up = np.where(rate > 0, (slabs.upper - base) / np.where(rate > 0, rate, 1), np.inf)
    down = np.where(rate < 0, (slabs.lower - base) / np.where(rate < 0, rate, 1), np.inf)
    return float(min(up.min(), down.min()))


def test_exact_hexacopter_reaches_more_yaw_than_pseudo_inverse() -> None:
    """Firefly at hover thrust: the polytope's max yaw equals the LP's and exceeds A⁺'s."""
    cfg = load_vehicle("firefly")
    A, lo, hi = allocation_matrix(cfg), 0.0, cfg.limits.rotor_speed_max**2
    exact, pinv = zonotope_slabs(A, lo, hi), pseudo_inverse_slabs(A, lo, hi)
    thrust = cfg.hover_thrust
    roll_max = linprog(-A[1], A_eq=A[[0, 2, 3]], b_eq=[thrust, 0, 0], bounds=(lo, hi),
                       method="highs").x @ A[1]
    gains = []
    for fraction in (0.0, 0.3, 0.6, 0.8):
        roll = fraction * roll_max
        lp = _max_yaw_lp(A, lo, hi, thrust, roll)
        assert max_yaw_slabs(exact, thrust, roll) == pytest.approx(lp, rel=1e-6)
        gains.append(lp / max_yaw_slabs(pinv, thrust, roll))
    print("yaw gain exact/A⁺ at roll 0, 30, 60, 80 % of the maximum:", np.round(gains, 3))
    # Without roll torque the equal-speed hover is A⁺'s and the LP's optimum alike.
    assert gains[0] == pytest.approx(1.0, rel=1e-6)
    assert min(gains[1:]) > 1.1 and gains[1] < gains[2] < gains[3]
    # At 90 % of the roll torque A⁺ has no solution at all, the polytope still one with yaw.
    roll = 0.9 * roll_max
    assert max_yaw_slabs(pinv, thrust, roll) == -np.inf
    assert max_yaw_slabs(exact, thrust, roll) == pytest.approx(
        _max_yaw_lp(A, lo, hi, thrust, roll), rel=1e-6)
    assert _max_yaw_lp(A, lo, hi, thrust, roll) > 0.0


def test_allocation_mode_from_the_vehicle_file(tmp_path: Path) -> None:
    """``[limits] allocation`` is read, round-trips, selects the slabs; a bad one is one line."""
    base = load_vehicle("firefly")
    assert base.allocation == "pseudo_inverse"
    text = vehicle_to_toml(replace(base, allocation="exact"))
    path = tmp_path / "hexa.toml"
    path.write_text(text, encoding="utf-8")
    exact = load_vehicle(path)
    assert exact.allocation == "exact"
    assert "allocation" not in vehicle_to_toml(base)
    hi = base.limits.rotor_speed_max**2
    assert allocation_slabs(exact, 0.0, hi).normals.shape[0] > base.rotor_count
    assert allocation_slabs(base, 0.0, hi).normals.shape[0] == base.rotor_count
    path.write_text(text.replace('allocation = "exact"', 'allocation = "lp"'), encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    message = str(info.value)
    assert "\n" not in message and "[limits].allocation" in message and "exact" in message
