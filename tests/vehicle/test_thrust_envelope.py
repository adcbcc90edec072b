"""Tests of the thrust envelope (`mavsysid.vehicle.thrust_envelope`) and of its users."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.flight.ground.trajectory_safety import flight_limits
from mavsysid.planner.feasibility import check_vertex_state
from mavsysid.planner.segments import VertexState
from mavsysid.vehicle.config import GRAVITY, SHIPPED_VEHICLES, load_vehicle
from mavsysid.vehicle.thrust_envelope import thrust_envelope

BOX = np.array([-10.0, -10.0, 0.0, 10.0, 10.0, 10.0])


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_envelope_from_the_limits_and_the_rotors(name):
    """Ratio bounds are ratio × g; rotor bounds all rotors' c_T n² at the limits, per mass."""
    cfg = load_vehicle(name)
    env = thrust_envelope(cfg)
    lim = cfg.limits
    assert env.ratio_min == pytest.approx(lim.thrust_min_ratio * GRAVITY, rel=1e-15)
    assert env.ratio_max == pytest.approx(lim.thrust_max_ratio * GRAVITY, rel=1e-15)
    per_rotor = np.array([lim.rotor_speed_min, lim.rotor_speed_max]) ** 2 * cfg.parameters.c_T
    np.testing.assert_allclose([env.rotor_min, env.rotor_max],
                               cfg.rotor_count * per_rotor / cfg.mass, rtol=1e-14)
    assert env.minimum == max(env.ratio_min, env.rotor_min)
    assert env.maximum == min(env.ratio_max, env.rotor_max)
    assert env.minimum < GRAVITY < env.maximum


@pytest.mark.parametrize("bound", ["ratio", "rotor"])
def test_streamer_limits_are_the_tighter_bound(firefly, bound):
    """flight_limits' thrust acceleration range is the envelope's, whichever bound is tighter."""
    lim = firefly.limits
    if bound == "rotor":  # rotors that cannot reach the ratio bounds
        firefly = replace(firefly, limits=replace(
            lim, thrust_min_ratio=0.01, thrust_max_ratio=100.0,
            rotor_speed_min=0.3 * lim.rotor_speed_max))
    env = thrust_envelope(firefly)
    limits = flight_limits(firefly, BOX)
    tight = (env.rotor_min, env.rotor_max) if bound == "rotor" else (env.ratio_min,
                                                                     env.ratio_max)
    assert (limits.thrust_acceleration_min, limits.thrust_acceleration_max) == tight
    assert limits.jerk_max == lim.body_rate_max * tight[1]


@pytest.mark.parametrize(("side", "factor", "feasible"),
                         [("max", 0.999, True), ("max", 1.001, False),
                          ("min", 1.001, True), ("min", 0.999, False)])
def test_planner_thrust_constraint_is_the_envelopes_ratio_bound(firefly, side, factor,
                                                                feasible):
    """A hover-like state accelerating up or down to the envelope's ratio bound is feasible
    just inside it and refused just outside (rotor check off: the thrust bound alone)."""
    env = thrust_envelope(firefly)
    target = (env.ratio_max if side == "max" else env.ratio_min) * factor
    state = VertexState.hover(np.array([0.0, 0.0, 5.0]), 0.0)
    position = state.position.copy()
    position[2, 2] = target - GRAVITY  # a_z, so that ‖a − g‖ = target
    state = replace(state, position=position)
    cfg = replace(firefly, limits=replace(firefly.limits, rotor_speed_min=0.0,
                                          rotor_speed_max=1e6))
    assert check_vertex_state(state, cfg, BOX) is feasible
