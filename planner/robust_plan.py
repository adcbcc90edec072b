"""Planning under the prior's spread: the most confident chance-constrained rotor check
that still admits a flight.

`PlannerSettings.rotor_confidence` makes every rotor limit hold at the prior θ plus z times
its first-order spread. With a wide prior (±50 %) hardly any flight passes at z = 1.645,
after an opening flight almost every one does. A re-planned flight (an opening flight,
an estimate, the rest planned from the posterior) therefore asks for the highest z of a
ladder at which the planner finds a flight, and reports the z it got.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from mavsysid.planner.plan_result import PlanProgress, PlanResult
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import JobFailedError

__all__ = ["CONFIDENCE_LADDER", "ConfidentPlan", "plan_most_confident"]

#: Normal quantiles tried in turn: 95 %, 84 %, 69 % per rotor and sample, then the prior θ.
CONFIDENCE_LADDER = (1.645, 1.0, 0.5, 0.0)


@dataclass(frozen=True)
class ConfidentPlan:
    """A plan and the rotor confidence z it was found at (0: at the prior θ only)."""

    result: PlanResult
    rotor_confidence: float


def plan_most_confident(config: VehicleConfig, settings: PlannerSettings,
                        ladder: Sequence[float] = CONFIDENCE_LADDER,
                        progress: Callable[[PlanProgress], None] | None = None
                        ) -> ConfidentPlan:
    """Plan at the first z of ``ladder`` that yields a flight.

    Each rung gets the whole of ``settings``' planning time (or sample budget), so a
    sample-budgeted request stays reproducible.

    Raises
    ------
    JobFailedError
        No rung found a flight (the last rung's message).
    InputError
        A bad request (as `mavsysid.planner.rrbt.plan`).
    """
    failure: JobFailedError | None = None
    for z in ladder:
        try:
            result = plan(config, replace(settings, rotor_confidence=float(z)), progress)
        except JobFailedError as error:
            failure = error
            continue
        return ConfidentPlan(result, float(z))
    assert failure is not None, "an empty confidence ladder"
    raise failure
