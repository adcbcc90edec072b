"""The planner's segment check with the exact allocation, against a dense LP check."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.planner.feasibility import check_segment
from mavsysid.planner.segments import Segment, VertexState, connect_fixed
from mavsysid.vehicle.allocation import allocation_matrix
from mavsysid.vehicle.allocation_polytope import wrench_reachable_lp
from mavsysid.vehicle.config import SHIPPED_VEHICLES, VehicleConfig, load_vehicle
from mavsysid.vehicle.flatness import flat_to_state

# A box large enough that the box constraint rarely decides, m.
BOX = np.array([-20.0, -20.0, -20.0, 20.0, 20.0, 20.0])
SEGMENTS = 400


def random_segment(rng: np.random.Generator) -> Segment:
    """A fixed-end segment, T ∈ [0.3, 2] s, with strong yaw (what A⁺ limits on a hexa)."""
    duration = rng.uniform(0.3, 2.0)
    scale = 10.0 ** rng.uniform(-2.5, -0.5)

    def state() -> VertexState:
        position = np.vstack([rng.uniform(-1, 1, 3), rng.normal(size=(4, 3))
                              * np.array([1.0, 3.0, 10.0, 40.0])[:, None] * scale])
        return VertexState(position, rng.normal(size=3) * np.array([1.0, 6.0, 40.0]) * scale)

    return connect_fixed(state(), state(), duration)


def dense_lp_feasible(segment: Segment, cfg: VehicleConfig) -> bool:
    """Every 1 ms sample's wrench reachable by some n² in the rotor box: one block LP, or
    for a square allocation (a quad) the one n² = A⁻¹ w checked against the box, to the
    LP's tolerance (1e-7 of the range)."""
    t = np.append(np.arange(0.0, segment.duration, 1e-3), segment.duration)
    state = flat_to_state(segment.flat_outputs(t), cfg)
    wrench = np.column_stack([state.thrust, state.torque])
    if not np.all(np.isfinite(wrench)):
        return False
    lo, hi = cfg.limits.rotor_speed_min**2, cfg.limits.rotor_speed_max**2
    A = allocation_matrix(cfg)
    if A.shape[0] == A.shape[1]:
        n2 = np.linalg.solve(A, wrench.T)
        tolerance = 1e-7 * (hi - lo)
        return bool(np.all((n2 >= lo - tolerance) & (n2 <= hi + tolerance)))
    return wrench_reachable_lp(A, lo, hi, wrench)


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_exact_check_accepts_no_segment_a_dense_lp_check_rejects(name: str) -> None:
    """400 seeded segments: 0 accepted that 1 ms LP sampling rejects; on the hexa the exact
    check accepts segments A⁺ rejects for their rotors."""
    base = load_vehicle(name)
    # Without the other dynamic limits, the rotors are what decides.
    cfg = replace(replace(base, allocation="exact"), limits=replace(
        base.limits, body_rate_max=100.0, yaw_acceleration_max=1e3, speed_max=100.0,
        thrust_min_ratio=0.01, thrust_max_ratio=10.0))
    pinv_cfg = replace(cfg, allocation="pseudo_inverse")
    rng = np.random.default_rng(2020)
    stats = dict.fromkeys(["accepted", "rotor_rejected", "exact_only", "false_accepts"], 0)
    for _ in range(SEGMENTS):
        segment = random_segment(rng)
        result = check_segment(segment, cfg, BOX)
        stats["rotor_rejected"] += result.reason == "rotor_speed"
        if not result.feasible:
            continue
        stats["accepted"] += 1
        pinv = check_segment(segment, pinv_cfg, BOX)
        stats["exact_only"] += pinv.reason == "rotor_speed"
        stats["false_accepts"] += not dense_lp_feasible(segment, cfg)
    print(name, stats)
    assert stats["false_accepts"] == 0
    assert stats["accepted"] >= 50 and stats["rotor_rejected"] >= 50
    if base.rotor_count > 4:
        assert stats["exact_only"] >= 5
    else:
        assert stats["exact_only"] == 0
