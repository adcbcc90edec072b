"""A plan within ArduCopter's stock limits fills its budget on a slow machine, or says why
it does not (planner/graph_search.py, planner/plan_result.py).

The machine is simulated: the planner's clock advances a fixed step each time it is read,
so a test sees the same search on an idle or an overloaded machine.
"""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.planner.rrbt import plan
from mavsysid.planner.search_stop import FULL_FLIGHT_SHARE
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

from tests.planner.test_move_time import STOCK

BUDGET = 20.0  # s
PLANNING = 30.0  # s, the default planning time


class SlowClock:
    """A clock that advances ``step`` s each time it is read."""

    def __init__(self, step: float) -> None:
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def _plan(seed: int, step: float, **change):
    settings = PlannerSettings(**{"budget": BUDGET, "planning_time": PLANNING, "seed": seed,
                                  "autopilot_limits": STOCK, "refine_steps": 200, **change})
    return plan(load_vehicle("quad_x"), settings, clock=SlowClock(step))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_stock_limits_fill_the_budget_on_a_slow_machine(seed):
    """With ~3000 clock reads in the search's share (a few dozen samples, where the paper's
    sampler needed thousands) the flight uses ≥ 90 % of the budget and nothing is noted."""
    result = _plan(seed, step=0.01)
    assert result.stats.search_stop == "filled"
    assert result.trajectory.duration >= FULL_FLIGHT_SHARE * BUDGET
    assert result.trajectory.duration <= BUDGET + 1e-9
    assert result.shortfall == ""


def test_a_search_out_of_time_says_so_and_why():
    """A search that runs out of its share of the planning time with a short flight says
    how short, that the time (and the busy machine) stopped it, how many connections
    were feasible and what refused the others, and suggests twice the time."""
    result = _plan(1, step=0.5)
    duration = result.trajectory.duration
    assert duration < FULL_FLIGHT_SHARE * BUDGET and result.stats.search_stop == "time"
    note = result.shortfall
    assert note.startswith(f"a {duration:.1f} s flight of the 20 s budget")
    assert f"stopped at its share of the {PLANNING:g} s planning time" in note
    assert "the machine was busy" in note
    refusals = result.stats.refusals
    assert sum(refusals.values()) + result.stats.edges == result.stats.edges_attempted
    assert f"{result.stats.edges} of {result.stats.edges_attempted} sampled connections" in note
    assert "\n" not in note and note.endswith(f"try --time {2 * PLANNING:g}")


def test_a_search_out_of_samples_suggests_more():
    """With a sample budget the note names it and suggests twice as many samples."""
    result = _plan(1, step=0.0, planning_time=np.inf, max_samples=2)
    assert result.trajectory.duration < FULL_FLIGHT_SHARE * BUDGET
    assert result.stats.search_stop == "samples"
    assert "the search stopped after its 2 samples" in result.shortfall
    assert result.shortfall.endswith("try --samples 4")
