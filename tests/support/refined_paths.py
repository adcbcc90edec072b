"""Checks every refined flight must pass, shared by the refinement tests."""

from __future__ import annotations

import pytest
from mavsysid.planner.belief import identity_transfer
from mavsysid.planner.graph_search import GraphSearch
from mavsysid.planner.refine import RefinablePath

__all__ = ["assert_consistent_flight"]


def assert_consistent_flight(search: GraphSearch, final: RefinablePath) -> None:
    """The refined flight's cached D-opt equals one priced from scratch, every segment is
    feasible, and it fits the budget."""
    fresh = [search.transfer_of(s) for s in final.segments]
    stop = identity_transfer() if final.stop.segment is None else search.transfer_of(
        final.stop.segment)
    assert search.flight_dopt([*fresh, stop]) == pytest.approx(final.dopt, rel=1e-8)
    assert all(search.feasible(s) for s in final.segments)
    assert final.duration <= search.settings.budget + 1e-9
