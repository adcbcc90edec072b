"""Tests of when the timed graph search stops (`search_time_is_up`)."""

from __future__ import annotations

import pytest
from mavsysid.planner.search_stop import (
    FULL_FLIGHT_SHARE,
    SEARCH_SHARE_MAX,
    search_time_is_up,
)

PLANNING = 5.0  # s
BUDGET = 30.0  # s
DEADLINE = 0.1 * PLANNING  # refine_share 0.9


@pytest.mark.parametrize("elapsed", [0.0, 0.2, DEADLINE - 1e-6])
@pytest.mark.parametrize("best", [None, 3.0, BUDGET])
def test_search_runs_until_its_share(elapsed, best):
    """Before its share of the planning time the search goes on, whatever it found."""
    assert not search_time_is_up(elapsed, DEADLINE, PLANNING, best, BUDGET)


@pytest.mark.parametrize("best", [None, 7.6, FULL_FLIGHT_SHARE * BUDGET - 0.01])
def test_a_short_best_flight_keeps_the_search_going(best):
    """Past its share, a search whose best flight leaves budget unused goes on."""
    assert not search_time_is_up(DEADLINE + 0.1, DEADLINE, PLANNING, best, BUDGET)


def test_a_full_best_flight_stops_the_search_at_its_share():
    """Past its share, a best flight using the budget ends the search."""
    assert search_time_is_up(DEADLINE, DEADLINE, PLANNING, FULL_FLIGHT_SHARE * BUDGET, BUDGET)


@pytest.mark.parametrize("best", [None, 2.0])
def test_the_refinement_keeps_its_part(best):
    """However short the best flight, the search stops at SEARCH_SHARE_MAX of the time."""
    assert search_time_is_up(SEARCH_SHARE_MAX * PLANNING, DEADLINE, PLANNING, best, BUDGET)


def test_a_search_given_most_of_the_time_stops_at_its_deadline():
    """With a share above SEARCH_SHARE_MAX (or no refinement) the deadline is final."""
    deadline = 0.8 * PLANNING
    assert search_time_is_up(deadline, deadline, PLANNING, 2.0, BUDGET)
    assert not search_time_is_up(deadline - 0.01, deadline, PLANNING, 2.0, BUDGET)
