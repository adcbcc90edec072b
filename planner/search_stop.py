"""When the timed graph search stops, and what stopped it.

The search gets 1 − refine_share of the planning time (`PlannerSettings.refine_share`),
more while its best flight leaves budget unused, and the refinement the rest. Time is
read from the search's clock (`mavsysid.planner.graph_search.GraphSearch`: the wall
clock unless one is given).
"""

from __future__ import annotations

__all__ = ["FULL_FLIGHT_SHARE", "SEARCH_SHARE_MAX", "search_stop", "search_time_is_up"]

#: The search runs past its share of the planning time while its best flight uses less
#: than this share of the budget: with 10 % of 5 s the search sometimes stopped at a 7.6 s
#: flight of a 30 s budget (4× worse D-opt), which no refinement of that path can lengthen.
#: The refinement keeps at least this share too (`mavsysid.planner.best_flight`).
FULL_FLIGHT_SHARE = 0.9
#: … but never past this share of the planning time, so the refinement keeps the rest.
SEARCH_SHARE_MAX = 0.5


def search_time_is_up(elapsed: float, deadline: float, planning_time: float,
                      best_flight: float | None, budget: float) -> bool:
    """Whether the graph search must stop (timed planning).

    Parameters
    ----------
    elapsed, deadline, planning_time : float
        Time since the search began, its share of the planning time, and the whole
        planning time, s.
    best_flight : float or None
        Duration of the best candidate flight so far, s (None: none yet).
    budget : float
        The flight's time budget, s.
    """
    if elapsed < deadline:
        return False
    if deadline >= SEARCH_SHARE_MAX * planning_time or elapsed >= SEARCH_SHARE_MAX * planning_time:
        return True
    return best_flight is not None and best_flight >= FULL_FLIGHT_SHARE * budget


def search_stop(samples_done: bool, time_up: bool, best_flight: float | None,
                budget: float) -> str:
    """What stops the search now: "samples" (its sample budget is spent), "filled" or
    "time" (its time is up with a flight that uses at least `FULL_FLIGHT_SHARE` of the
    budget, or not), or "" (it goes on).

    Parameters
    ----------
    samples_done, time_up : bool
        The sample budget is spent; `search_time_is_up`.
    best_flight : float or None
        Duration of the best candidate flight so far, s (None: none yet).
    budget : float
        The flight's time budget, s.
    """
    if samples_done:
        return "samples"
    if not time_up:
        return ""
    filled = best_flight is not None and best_flight >= FULL_FLIGHT_SHARE * budget
    return "filled" if filled else "time"
