"""A flight read with another vehicle's file than the one it was flown as (its meta.json)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.readers.recorded_vehicle import vehicle_differences
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError


@pytest.fixture(scope="module")
def micro_quad_flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An 8 s simulated micro_quad flight: pose.csv and the meta.json that records the vehicle."""
    directory = tmp_path_factory.mktemp("micro_quad")
    Simulator(load_vehicle("micro_quad"), settings=SimulationSettings(seed=3)).run(
        excitation_trajectory(ExcitationSpec(duration=8.0)), directory)
    return directory / "pose.csv"


def test_another_vehicles_file_is_refused_in_one_line(micro_quad_flight: Path) -> None:
    """Read with quad_x's file, the micro_quad flight is refused, naming both vehicles and
    what differs."""
    with pytest.raises(InputError) as error:
        load_flight(micro_quad_flight, load_vehicle("quad_x"))
    message = str(error.value)
    assert "\n" not in message
    assert "flown as vehicle micro_quad" in message and "--vehicle quad_x" in message
    assert "mass" in message and "rotor geometry" in message


def test_the_same_vehicle_edited_is_a_warning(micro_quad_flight: Path) -> None:
    """The micro_quad file with the mass re-weighed: read, with a warning that says so."""
    config = load_vehicle("micro_quad")
    heavier = replace(config, mass=config.mass * 1.1)
    flight = load_flight(micro_quad_flight, heavier)
    assert [w for w in flight.warnings if "differs from the one the flight was flown with" in w]
    plain = load_flight(micro_quad_flight, config)
    assert not [w for w in plain.warnings if "flown with" in w]


def test_differences_name_what_the_estimate_takes_as_known() -> None:
    """θ and noise may differ (they are the prior); mass, rotors, curve and frame may not."""
    config = load_vehicle("sitl_quad")
    assert vehicle_differences(config, config.with_parameters(config.theta * 1.3)) == []
    moved = replace(config, rotors=(replace(config.rotors[0], direction=-1),
                                    *config.rotors[1:]))
    assert vehicle_differences(config, moved) == ["rotor geometry (rotor 1)"]
    curve = replace(config, motor=replace(config.motor, pwm_min=1000.0))
    assert [d.split(" (")[0] for d in vehicle_differences(config, curve)] == ["motor curve"]
