"""Planning at the most confident rotor check that still admits a flight."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.planner.robust_plan import ConfidentPlan, plan_most_confident
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.trajectory import Trajectory

from mavsysid.errors import JobFailedError


def settings(**kw) -> PlannerSettings:
    """A short sample-budgeted request (reproducible), refined far enough that the
    unguarded plan reaches the rotor limits."""
    return PlannerSettings(budget=6.0, planning_time=np.inf, max_samples=120, seed=4,
                           refine_steps=3000, **kw)


@pytest.fixture(scope="module")
def confident_plan() -> ConfidentPlan:
    """The quad_x plan at z = 1.645 and a prior σ of 10 % (planned once for the module)."""
    return plan_most_confident(load_vehicle("quad_x"), settings(prior_relative_sigma=0.1),
                               ladder=(1.645,))


def _in_range(flight: Trajectory, worst: int) -> bool:
    """Whether the flight's rotor speeds (1 ms samples) stay in quad_x's range with θ[worst]
    1.5 σ (σ = 10 %) below the prior."""
    cfg = load_vehicle("quad_x")
    theta = cfg.theta.copy()
    theta[worst] *= 1 - 1.5 * 0.1
    t = np.linspace(0.0, flight.duration, 1 + int(1000 * flight.duration))
    squared = flat_to_state(flight.flat_outputs(t), cfg, theta).rotor_speeds_squared
    lim = cfg.limits
    return bool(np.all(squared <= (lim.rotor_speed_max * (1 + 1e-9)) ** 2)
                and np.all(squared >= (lim.rotor_speed_min * (1 - 1e-9)) ** 2))


@pytest.mark.slow
@pytest.mark.parametrize("worst", [0, 2])
def test_the_flight_keeps_its_rotors_in_range_for_theta_within_the_reported_spread(
        confident_plan: ConfidentPlan, worst: int) -> None:
    """At z = 1.645 and σ = 10 %, the flight's rotor speeds stay in range with c_T (or c_M)
    1.5 σ below the prior."""
    assert confident_plan.rotor_confidence == 1.645
    assert _in_range(confident_plan.result.trajectory, worst)


@pytest.mark.slow
def test_the_unguarded_plan_would_leave_the_range() -> None:
    """The premise: planned at the prior θ alone, the same request leaves the rotor range
    with c_M 1.5 σ below the prior."""
    unguarded = plan(load_vehicle("quad_x"), settings(prior_relative_sigma=0.1))
    assert not _in_range(unguarded.trajectory, 2)


def test_a_ladder_with_no_feasible_rung_fails_in_one_line() -> None:
    """With a prior spread no hover survives, every rung fails and the error is raised."""
    cfg = load_vehicle("firefly")
    with pytest.raises(JobFailedError):
        plan_most_confident(cfg, settings(prior_relative_sigma=0.5), ladder=(6.0,))
