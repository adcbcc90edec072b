"""Tests of the one validator of a planning request (`mavsysid.planner.plan_request`):
its boundaries, and that the planner and the random baseline refuse what it refuses."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.planner.baseline import plan_random
from mavsysid.planner.plan_request import MIN_BOX_SIDE, check_request, rotor_clearance
from mavsysid.planner.results import PlannerSettings
from mavsysid.planner.rrbt import plan
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.mav_model import rotor_speed_for_thrust

from mavsysid.errors import ConfigError, InputError


@pytest.fixture(scope="module")
def firefly() -> VehicleConfig:
    return load_vehicle("firefly")


def _with_limits(config: VehicleConfig, **limits: float) -> VehicleConfig:
    return replace(config, limits=replace(config.limits, **limits))


def _idle_speed(config: VehicleConfig, factor: float) -> float:
    """The rotor speed at which the rotors together lift ``factor`` × m g, rad/s."""
    per_rotor = factor * config.hover_thrust / config.rotor_count
    return float(rotor_speed_for_thrust(config.parameters.c_T, per_rotor))


# (limits as a function of the vehicle, refused?) around each hover boundary.
HOVER_CASES = {
    "T_max = m g": (lambda c: {"thrust_max_ratio": 1.0}, True),
    "T_max just above m g": (lambda c: {"thrust_max_ratio": 1.0 + 1e-9}, False),
    "T_max below m g": (lambda c: {"thrust_max_ratio": 0.9, "thrust_min_ratio": 0.5}, True),
    "T_min = m g": (lambda c: {"thrust_min_ratio": 1.0}, True),
    "T_min just below m g": (lambda c: {"thrust_min_ratio": 1.0 - 1e-9}, False),
    "idle lift just above m g": (lambda c: {"rotor_speed_min": _idle_speed(c, 1.0 + 1e-9)}, True),
    "idle lift just below m g": (lambda c: {"rotor_speed_min": _idle_speed(c, 0.5)}, False),
}


@pytest.mark.parametrize(("limits", "refused"), HOVER_CASES.values(), ids=HOVER_CASES.keys())
def test_hover_boundaries(firefly, limits, refused):
    """T_min < m g < T_max strictly, and idle rotors lifting less than m g: a vehicle whose
    greatest thrust equals its weight has no margin to hover with."""
    config = _with_limits(firefly, **limits(firefly))
    settings = PlannerSettings(max_samples=5, planning_time=math.inf)
    if refused:
        key = next(iter(limits(firefly)))
        with pytest.raises(ConfigError, match=rf"\[limits\]\.{key}"):
            check_request(config, settings)
    else:
        check_request(config, settings)


def _box_with_x_side(side: float) -> tuple[float, ...]:
    """The default box with the x side set to ``side`` m, centred on 0."""
    box = list(PlannerSettings.box)
    box[0], box[3] = -side / 2.0, side / 2.0
    return tuple(box)


@pytest.mark.parametrize(("shrink", "refused"), [(0.0, False), (1e-6, True)])
def test_box_side_boundary(firefly, shrink, refused):
    """The shortest box side: max(MIN_BOX_SIDE, twice the rotor clearance), inclusive."""
    need = max(MIN_BOX_SIDE, 2.0 * rotor_clearance(firefly))
    settings = PlannerSettings(box=_box_with_x_side(need - shrink))  # type: ignore[arg-type]
    if refused:
        with pytest.raises(InputError, match=r"^--box .*: the x side is .* needs at least"):
            check_request(firefly, settings)
    else:
        check_request(firefly, settings)


def test_min_box_side_holds_for_a_tiny_vehicle(firefly):
    """A vehicle whose rotors nearly touch still needs MIN_BOX_SIDE of room."""
    tiny = replace(firefly, rotors=tuple(
        replace(r, position=tuple(1e-3 * v for v in r.position)) for r in firefly.rotors))
    assert 2.0 * rotor_clearance(tiny) < MIN_BOX_SIDE
    check_request(tiny, PlannerSettings(box=_box_with_x_side(MIN_BOX_SIDE)))  # type: ignore[arg-type]
    with pytest.raises(InputError, match="the x side is"):
        check_request(tiny, PlannerSettings(box=_box_with_x_side(0.9 * MIN_BOX_SIDE)))  # type: ignore[arg-type]


@pytest.mark.parametrize(("inset", "refused"), [(0.0, False), (1e-6, True)])
def test_start_margin_boundary(firefly, inset, refused):
    """The start hover keeps the rotors inside the box: at least the clearance from a wall."""
    box = PlannerSettings.box
    x = box[3] - rotor_clearance(firefly) + inset
    settings = PlannerSettings(start=(x, 0.0, 1.5, 0.0))
    if refused:
        with pytest.raises(InputError, match=r"^--start .* must start at least"):
            check_request(firefly, settings)
    else:
        check_request(firefly, settings)


# Requests refused by both `mavsysid plan` and the planner, with the option each names.
BAD_REQUESTS = {
    "budget 0": ({"budget": 0.0}, "^--budget"),
    "budget inf": ({"budget": math.inf}, "^--budget"),
    "samples 0": ({"max_samples": 0}, "^--samples"),
    "no limit at all": ({"planning_time": math.inf, "max_samples": None}, "^--time"),
    "negative seed": ({"seed": -1}, "^--seed"),
    "refine split 0": ({"refine_split": 0}, "^refinement"),
    "box min above max": ({"box": (2.0, -2.0, 0.5, -2.0, 2.0, 2.5)}, "x_min must be below"),
    "box too small": ({"box": (-2.0, -2.0, 1.0, 2.0, 2.0, 1.3)}, "the z side is"),
    "start outside": ({"start": (3.0, 0.0, 1.5, 0.0)}, "^--start"),
    "headroom 0.5": ({"rotor_headroom": 0.5}, "^--rotor-headroom"),
}


@pytest.mark.parametrize(("change", "fragment"), BAD_REQUESTS.values(), ids=BAD_REQUESTS.keys())
@pytest.mark.parametrize("planner", [check_request, plan, plan_random],
                         ids=["check_request", "plan", "plan_random"])
def test_planners_refuse_what_the_validator_refuses(firefly, planner, change, fragment):
    """The planner and the baseline check with the same validator, before any search."""
    settings = replace(PlannerSettings(max_samples=5, planning_time=math.inf), **change)
    with pytest.raises(InputError, match=fragment):
        planner(firefly, settings)


def test_planner_refuses_a_vehicle_without_hover_margin(firefly):
    """T_max = m g: refused by the planner too (it accepted it before the validators merged)."""
    config = _with_limits(firefly, thrust_max_ratio=1.0)
    with pytest.raises(ConfigError, match="thrust_max_ratio"):
        plan(config, PlannerSettings(max_samples=5, planning_time=np.inf))
