"""Tests of vehicle configs: shipped files, defaults, round trip and schema errors."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from pathlib import Path

import pytest
from mavsysid.vehicle.config import (
    GRAVITY,
    SHIPPED_VEHICLES,
    Limits,
    MotorConfig,
    VehicleConfig,
    load_vehicle,
    save_vehicle,
    vehicle_to_toml,
)
from mavsysid.vehicle.config_checks import (
    INERTIA_TRIANGLE_SLACK,
    InertiaWarning,
    triangle_violation,
)

from mavsysid.cli.main import exit_code
from mavsysid.errors import ConfigError, InputError

BAD_VEHICLES = Path(__file__).resolve().parents[1] / "data" / "bad_vehicles"

# A valid X quad with only the required keys; malformed cases edit one piece of it.
MINIMAL = """\
mass = 1.0

[[rotors]]
position = [0.12, 0.12, 0.0]
direction = 1

[[rotors]]
position = [-0.12, 0.12, 0.0]
direction = -1

[[rotors]]
position = [-0.12, -0.12, 0.0]
direction = 1

[[rotors]]
position = [0.12, -0.12, 0.0]
direction = -1

[parameters]
c_T = 6.8e-6
c_D = 0.012
c_M = 1.02e-7
J = [0.0082, 0.0082, 0.0149]

[limits]
rotor_speed_max = 1150.0
"""

ROTOR_3 = "position = [-0.12, -0.12, 0.0]\ndirection = 1\n"


def _write(tmp_path: Path, text: str, name: str = "vehicle.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _edit(old: str, new: str) -> str:
    assert old in MINIMAL, old
    return MINIMAL.replace(old, new)


def _load_error(path: Path | str) -> str:
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    return str(info.value)


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_shipped_config_loads_by_name(name: str) -> None:
    """Each shipped name loads, with name = NAME and source = builtin:NAME."""
    config = load_vehicle(name)
    assert isinstance(config, VehicleConfig)
    assert config.name == name
    assert config.source == f"builtin:{name}"
    assert config.rotor_count >= 4


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_shipped_config_hovers_with_margin(name: str) -> None:
    """Each shipped vehicle's rotors give at least twice its weight at top speed."""
    config = load_vehicle(name)
    lift = config.rotor_count * config.parameters.c_T * config.limits.rotor_speed_max**2
    assert lift >= 2.0 * config.mass * GRAVITY
    # The planner's upper thrust limit must be reachable by the rotors.
    assert lift >= config.limits.thrust_max_ratio * config.hover_thrust


def test_firefly_matches_design_reference_table() -> None:
    """firefly.toml holds exactly the docs/architecture.md reference values (AscTec Firefly)."""
    config = load_vehicle("firefly")
    assert config.mass == 1.56779
    assert config.rotor_count == 6
    angles = (30.0, 90.0, 150.0, 210.0, 270.0, 330.0)
    for rotor, angle, direction in zip(config.rotors, angles, (1, -1, 1, -1, 1, -1), strict=True):
        a = math.radians(angle)
        expected = (0.215 * math.cos(a), 0.215 * math.sin(a), 0.037)
        assert rotor.position == pytest.approx(expected, abs=1e-12)
        assert rotor.direction == direction
    p = config.parameters
    assert (p.c_T, p.c_D, p.c_M) == (8.54858e-6, 0.0176, 1.36777e-7)
    assert p.J == (0.0347563, 0.0458929, 0.0770492)
    assert config.limits.rotor_speed_max == 838.0
    assert config.motor.time_constant == 0.025
    assert config.noise.position_sigma == 0.0005
    assert config.noise.attitude_sigma == math.radians(0.1)


@pytest.mark.parametrize(
    ("name", "mass", "c_T", "ratio", "rotor_speed_max", "time_constant"),
    [
        ("quad_x", 1.0, 6.8e-6, 0.015, 1150.0, 0.02),
        ("micro_quad", 0.030, 2.0e-8, 0.006, 2900.0, 0.015),
    ],
)
def test_quad_configs_match_their_specification(
    name: str, mass: float, c_T: float, ratio: float, rotor_speed_max: float,
    time_constant: float,
) -> None:
    """The shipped quads hold the specified mass, c_T, c_M = ratio × c_T and limits."""
    config = load_vehicle(name)
    assert config.mass == mass
    assert config.parameters.c_T == c_T
    assert config.parameters.c_M == pytest.approx(ratio * c_T, rel=1e-12)
    assert config.limits.rotor_speed_max == rotor_speed_max
    assert config.motor.time_constant == time_constant
    assert list(config.rotor_directions) == [1, -1, 1, -1]


def test_minimal_file_loads_with_documented_defaults(tmp_path: Path) -> None:
    """A file with only required keys loads; optional keys take the documented defaults."""
    path = _write(tmp_path, MINIMAL, "my_quad.toml")
    config = load_vehicle(path)
    assert config.name == "my_quad"
    assert config.source == str(path)
    assert config.limits == Limits(rotor_speed_max=1150.0)
    assert (config.limits.rotor_speed_min, config.limits.thrust_min_ratio) == (0.0, 0.5)
    assert config.limits.thrust_max_ratio == 1.8
    assert config.limits.body_rate_max == 3.0
    assert config.limits.yaw_acceleration_max == 2.0 * math.pi
    assert (config.limits.speed_max, config.limits.segment_time_max) == (3.0, 3.0)
    assert config.motor == MotorConfig()
    assert (config.motor.pwm_min, config.motor.pwm_max) == (1000.0, 2000.0)
    assert config.motor.thrust_expo == 0.65
    noise = config.noise
    assert noise.position_sigma == 0.0005
    assert noise.attitude_sigma == math.radians(0.1)
    assert noise.rotor_speed_sigma == 0.0
    assert noise.force_density == pytest.approx(0.02 * 1.0)
    assert noise.moment_density == pytest.approx(0.02 * (0.0082 + 0.0082 + 0.0149) / 3)


def test_name_key_overrides_file_stem(tmp_path: Path) -> None:
    """A top-level `name` key names a config loaded from a path."""
    config = load_vehicle(_write(tmp_path, 'name = "bench rig"\n' + MINIMAL))
    assert config.name == "bench rig"


def test_optional_keys_are_read(tmp_path: Path) -> None:
    """Optional [limits], [motor] and [noise] keys override the defaults."""
    text = MINIMAL + (
        "speed_max = 2\nrotor_speed_min = 100.0\n\n[motor]\ntime_constant = 0\n"
        "pwm_min = 1100\npwm_max = 1900\nthrust_expo = 0.5\n\n"
        "[noise]\nforce_density = 0.5\nattitude_sigma = 0.01\n"
    )
    config = load_vehicle(_write(tmp_path, text))
    assert config.limits.speed_max == 2.0
    assert isinstance(config.limits.speed_max, float)
    assert config.limits.rotor_speed_min == 100.0
    assert config.motor == MotorConfig(time_constant=0.0, pwm_min=1100.0, pwm_max=1900.0,
                                       thrust_expo=0.5)
    assert config.noise.force_density == 0.5
    assert config.noise.attitude_sigma == 0.01


@pytest.mark.parametrize("name", SHIPPED_VEHICLES)
def test_vehicle_to_toml_round_trips(name: str, tmp_path: Path) -> None:
    """vehicle_to_toml + load_vehicle gives back an equal config (all but source)."""
    config = load_vehicle(name)
    path = tmp_path / "copy.toml"
    save_vehicle(config, path)
    assert path.read_text(encoding="utf-8") == vehicle_to_toml(config)
    again = load_vehicle(path)
    assert dataclasses.replace(again, source=config.source) == config
    assert again.source == str(path)


def test_vehicle_to_toml_escapes_name(tmp_path: Path) -> None:
    """Names with quotes, backslashes and control characters survive the round trip."""
    config = dataclasses.replace(load_vehicle("quad_x"), name='a "quoted"\\ name\t\x7f é')
    path = _write(tmp_path, vehicle_to_toml(config))
    assert load_vehicle(path).name == config.name


MALFORMED = [
    pytest.param(_edit("mass = 1.0", "mass = = 1.0"), "line 1", id="toml-syntax"),
    pytest.param(_edit("mass = 1.0\n", ""), "mass", id="missing-mass"),
    pytest.param(_edit("mass = 1.0", "mass = true"), "mass", id="mass-bool"),
    pytest.param(_edit("mass = 1.0", 'mass = "1.0"'), "mass", id="mass-string"),
    pytest.param(_edit("mass = 1.0", "mass = -1.0"), "mass", id="mass-negative"),
    pytest.param(_edit("mass = 1.0", "mass = nan"), "mass", id="mass-nan"),
    pytest.param(_edit("mass = 1.0", 'mass = 1.0\nname = ""'), "name", id="name-empty"),
    pytest.param(_edit("c_T = 6.8e-6\n", ""), "[parameters].c_T", id="missing-c_T"),
    pytest.param(_edit("c_T = 6.8e-6", "c_T = 0"), "[parameters].c_T", id="c_T-zero"),
    pytest.param(_edit("c_T = 6.8e-6", "c_T = inf"), "[parameters].c_T", id="c_T-inf"),
    pytest.param(_edit("c_D = 0.012", "c_D = -0.012"), "[parameters].c_D", id="c_D-negative"),
    pytest.param(_edit("c_M = 1.02e-7", "c_M = 0.015"), "[parameters].c_M", id="c_M-ratio"),
    pytest.param(_edit("c_M = 1.02e-7", "c_M = false"), "[parameters].c_M", id="c_M-bool"),
    pytest.param(_edit("J = [0.0082, 0.0082, 0.0149]", "J = [0.0082, 0.0082]"),
                 "[parameters].J", id="J-two-numbers"),
    pytest.param(_edit("J = [0.0082, 0.0082, 0.0149]", "J = [0.0082, 0.0, 0.0149]"),
                 "[parameters].J", id="J-zero"),
    pytest.param(_edit("J = [0.0082, 0.0082, 0.0149]", "J = [0.0082, true, 0.0149]"),
                 "[parameters].J", id="J-bool"),
    pytest.param(_edit("[parameters]\n", "[params]\n"), "[params]", id="unknown-table"),
    pytest.param(_edit("rotor_speed_max = 1150.0\n", ""), "[limits].rotor_speed_max",
                 id="missing-rotor_speed_max"),
    pytest.param(_edit("[limits]\nrotor_speed_max = 1150.0\n", ""), "[limits]",
                 id="missing-limits"),
    pytest.param(_edit("rotor_speed_max = 1150.0", "rotor_speed_max = 500.0"),
                 "[limits].rotor_speed_max", id="cannot-lift"),
    pytest.param(MINIMAL + "rotor_speed_min = 1150.0\n", "[limits].rotor_speed_min",
                 id="rotor_speed_min-too-high"),
    pytest.param(MINIMAL + "rotor_speed_min = -1.0\n", "[limits].rotor_speed_min",
                 id="rotor_speed_min-negative"),
    pytest.param(MINIMAL + "thrust_min_ratio = 2.0\n", "[limits].thrust_min_ratio",
                 id="thrust-ratios-reversed"),
    pytest.param(MINIMAL + "body_rate_max = 0\n", "[limits].body_rate_max",
                 id="body_rate_max-zero"),
    pytest.param(MINIMAL + "segment_time_max = -3\n", "[limits].segment_time_max",
                 id="segment_time_max-negative"),
    pytest.param(MINIMAL + "\n[motor]\ntime_constant = -0.01\n", "[motor].time_constant",
                 id="motor-negative"),
    pytest.param(MINIMAL + "\n[motor]\npwm_min = 2000\npwm_max = 1000\n", "[motor].pwm_min",
                 id="pwm-reversed"),
    pytest.param(MINIMAL + "\n[motor]\npwm_max = 900\n", "[motor].pwm_min",
                 id="pwm_max-below-default-min"),
    pytest.param(MINIMAL + "\n[motor]\nthrust_expo = 1.5\n", "[motor].thrust_expo",
                 id="thrust_expo-above-1"),
    pytest.param(MINIMAL + "\n[motor]\nthrust_expo = -0.1\n", "[motor].thrust_expo",
                 id="thrust_expo-negative"),
    pytest.param(MINIMAL + "\n[noise]\nposition_sigma = -0.001\n", "[noise].position_sigma",
                 id="noise-negative"),
    pytest.param(MINIMAL + "\n[noise]\nmoment_density = [1.0]\n", "[noise].moment_density",
                 id="noise-array"),
    pytest.param(_edit(ROTOR_3, ROTOR_3.replace("= 1", "= 0")), "[[rotors]][3].direction",
                 id="direction-zero"),
    pytest.param(_edit(ROTOR_3, ROTOR_3.replace("= 1", "= true")), "[[rotors]][3].direction",
                 id="direction-bool"),
    pytest.param(_edit(ROTOR_3, "direction = 1\n"), "[[rotors]][3].position",
                 id="missing-position"),
    pytest.param(_edit(ROTOR_3, "position = [-0.12, -0.12]\ndirection = 1\n"),
                 "[[rotors]][3].position", id="position-two-numbers"),
    pytest.param(_edit(ROTOR_3, ROTOR_3 + "postion = [0.0, 0.0, 0.0]\n"),
                 "[[rotors]][3].postion", id="unknown-rotor-key"),
    pytest.param(_edit("[[rotors]]\n" + ROTOR_3, ""), "[[rotors]]", id="three-rotors"),
    pytest.param(MINIMAL.replace("direction = -1", "direction = 1"), "[[rotors]].direction",
                 id="same-directions"),
    pytest.param(MINIMAL.replace("direction = -1", "direction = 1").replace(
        ROTOR_3, ROTOR_3.replace("= 1", "= -1")).replace(
        "[0.12, -0.12, 0.0]\ndirection = 1", "[0.12, -0.12, 0.0]\ndirection = -1"),
        "[[rotors]].direction", id="yaw-follows-roll"),
    pytest.param(MINIMAL.replace("[-0.12, 0.12, 0.0]", "[0.0, 0.0, 0.0]").replace(
        "[0.12, -0.12, 0.0]", "[0.06, 0.06, 0.0]"), "[[rotors]].position",
        id="rotors-on-a-line"),
    pytest.param("mass = 1.0\nrotors = 4\n" + MINIMAL[MINIMAL.index("[parameters]"):],
                 "[[rotors]]", id="rotors-not-tables"),
    pytest.param(MINIMAL + "\n[noise]\nunknown = 1\n", "[noise].unknown", id="unknown-key"),
]


def test_inertia_breaking_triangle_inequality_warns_and_loads(tmp_path: Path) -> None:
    """A prior is a guess: an inertia beyond the triangle slack is warned about, not refused."""
    path = _write(tmp_path, _edit("J = [0.0082, 0.0082, 0.0149]", "J = [0.0082, 0.0082, 0.149]"))
    with pytest.warns(InertiaWarning) as record:
        config = load_vehicle(path)
    assert config.parameters.J == (0.0082, 0.0082, 0.149)
    message = str(record[0].message)
    assert "\n" not in message
    assert str(path) in message or path.name in message
    assert "[parameters].J" in message and "j_x + j_y" in message


def test_inertia_within_triangle_slack_does_not_warn(tmp_path: Path) -> None:
    """The shipped Firefly and an inertia inside the triangle slack load silently."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", InertiaWarning)
        load_vehicle("firefly")
        load_vehicle(_write(tmp_path, _edit("J = [0.0082, 0.0082, 0.0149]",
                                            "J = [0.0082, 0.0082, 0.0204]")))


@pytest.mark.parametrize(("j", "expected"), [
    ((1.0, 1.0, 1.0), None),
    ((1.0, 1.0, 2.0 * (1.0 + INERTIA_TRIANGLE_SLACK)), None),
    ((1.0, 1.0, 2.0 * (1.0 + INERTIA_TRIANGLE_SLACK) * 1.001), (2, 0, 1)),
    ((5.0, 1.0, 1.0), (0, 1, 2)),
    ((1.0, 5.0, 1.0), (1, 2, 0)),
])
def test_triangle_violation(j: tuple[float, float, float],
                            expected: tuple[int, int, int] | None) -> None:
    assert triangle_violation(j) == expected


@pytest.mark.parametrize(("text", "key"), MALFORMED)
def test_malformed_config_raises_one_line_error(tmp_path: Path, text: str, key: str) -> None:
    """Each malformed file raises a one-line ConfigError naming the file and the key."""
    path = _write(tmp_path, text, "broken_vehicle.toml")
    message = _load_error(path)
    assert "\n" not in message and "\r" not in message
    assert message.startswith(f"{path}: ")
    assert key in message
    assert ", got " in message


def test_config_error_is_an_input_error(tmp_path: Path) -> None:
    """ConfigError is an InputError, so the CLI maps it to exit code 2."""
    with pytest.raises(InputError) as info:
        load_vehicle(_write(tmp_path, _edit("mass = 1.0\n", "")))
    assert exit_code(info.value) == 2


@pytest.mark.parametrize(
    ("old", "new", "suggestion"),
    [
        ("mass = 1.0", "mas = 1.0", "did you mean mass?"),
        ("c_T = 6.8e-6", "c_t = 6.8e-6", "did you mean [parameters].c_T?"),
        ("rotor_speed_max = 1150.0", "rotor_speed_maximum = 1150.0",
         "did you mean [limits].rotor_speed_max?"),
        ("[limits]", "[limit]", "did you mean [limits]?"),
        ("mass = 1.0", "mass = 1.0\nc_D = 0.012", "did you mean [parameters].c_D?"),
    ],
)
def test_near_typo_gets_suggestion(tmp_path: Path, old: str, new: str, suggestion: str) -> None:
    """A misspelt or misplaced key is reported with a "did you mean …?" suggestion."""
    message = _load_error(_write(tmp_path, _edit(old, new)))
    assert suggestion in message
    assert "\n" not in message


def test_c_M_ratio_message_gives_absolute_value(tmp_path: Path) -> None:
    """A c_M that is RotorS's ratio is rejected with the absolute coefficient ratio × c_T."""
    message = _load_error(_write(tmp_path, _edit("c_M = 1.02e-7", "c_M = 0.015")))
    assert "ratio c_M/c_T" in message
    assert "1.02e-07" in message


def test_cannot_lift_message_gives_both_forces(tmp_path: Path) -> None:
    """The lift check names rotor_speed_max and gives the weight and maximum thrust in N."""
    text = _edit("rotor_speed_max = 1150.0", "rotor_speed_max = 500.0")
    message = _load_error(_write(tmp_path, text))
    assert "9.81 N" in message
    assert f"{4 * 6.8e-6 * 500.0**2:.6g} N" in message


@pytest.mark.parametrize("spec", ["fireflly", "no_such_vehicle.toml"])
def test_unknown_spec_lists_shipped_names(spec: str, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A spec that is neither a shipped name nor a file names the spec and the shipped names."""
    monkeypatch.chdir(tmp_path)
    message = _load_error(spec)
    assert message.startswith(spec)
    assert all(name in message for name in SHIPPED_VEHICLES)
    assert "\n" not in message


def test_bad_vehicles_directory_is_complete() -> None:
    """tests/data/bad_vehicles holds exactly the five files listed in expected.json."""
    expected = json.loads((BAD_VEHICLES / "expected.json").read_text(encoding="utf-8"))
    assert sorted(p.name for p in BAD_VEHICLES.glob("*.toml")) == sorted(expected)
    assert len(expected) == 5


@pytest.mark.parametrize(
    "file_name",
    sorted(json.loads((BAD_VEHICLES / "expected.json").read_text(encoding="utf-8"))),
)
def test_bad_vehicle_file_names_its_key(file_name: str) -> None:
    """Each file in tests/data/bad_vehicles fails with the key text of expected.json."""
    expected = json.loads((BAD_VEHICLES / "expected.json").read_text(encoding="utf-8"))
    message = _load_error(BAD_VEHICLES / file_name)
    assert file_name in message
    assert expected[file_name] in message
    assert "\n" not in message
