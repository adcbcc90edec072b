"""The autopilots' motor numbering and its mapping onto a config's rotor order."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.vehicle.config import RotorConfig, load_vehicle, save_vehicle
from mavsysid.vehicle.motor_order import (
    AUTOPILOT_FRAMES,
    FRAME_NAMES,
    MotorOrderError,
    output_to_rotor,
)

from mavsysid.errors import ConfigError

CCW, CW = +1, -1
C30, S30 = math.sqrt(3.0) / 2.0, 0.5
C22, S22 = math.cos(math.pi / 8.0), math.sin(math.pi / 8.0)
H = math.sqrt(0.5)

# Motor 1, 2, … of each frame as body-FLU unit vectors (x forward, y LEFT) and spin seen
# from above, written by hand from the sources' rotor names (PX4's geometry files call them
# "front_right", "mid_left", …; ArduPilot's quad X is front right, rear left, front left,
# rear right), not computed from the tables' clockwise angles.
PUBLISHED = {
    # 1 front right CCW, 2 rear left CCW, 3 front left CW, 4 rear right CW
    "quad_x": [((H, -H), CCW), ((-H, H), CCW), ((H, H), CW), ((-H, -H), CW)],
    # 1 right CCW, 2 left CCW, 3 front CW, 4 rear CW
    "quad_plus": [((0, -1), CCW), ((0, 1), CCW), ((1, 0), CW), ((-1, 0), CW)],
    # 1 right CW, 2 left CCW, 3 front left CW, 4 rear right CCW, 5 front right CCW,
    # 6 rear left CW
    "hexa_x": [((0, -1), CW), ((0, 1), CCW), ((C30, S30), CW), ((-C30, -S30), CCW),
               ((C30, -S30), CCW), ((-C30, S30), CW)],
    # 1 front CW, 2 rear CCW, 3 rear left CW, 4 front right CCW, 5 front left CCW,
    # 6 rear right CW
    "hexa_plus": [((1, 0), CW), ((-1, 0), CCW), ((-S30, C30), CW), ((S30, -C30), CCW),
                  ((S30, C30), CCW), ((-S30, -C30), CW)],
    # 1 front right CW, 2 rear left CW, 3 mid front right CCW, 4 rear right CCW,
    # 5 front left CCW, 6 mid rear left CCW, 7 mid front left CW, 8 mid rear right CW
    "octa_x": [((C22, -S22), CW), ((-C22, S22), CW), ((S22, -C22), CCW), ((-C22, -S22), CCW),
               ((C22, S22), CCW), ((-S22, C22), CCW), ((S22, C22), CW), ((-S22, -C22), CW)],
    # 1 front CW, 2 rear CW, 3 front right CCW, 4 rear right CCW, 5 front left CCW,
    # 6 rear left CCW, 7 left CW, 8 right CW
    "octa_plus": [((1, 0), CW), ((-1, 0), CW), ((H, -H), CCW), ((-H, -H), CCW), ((H, H), CCW),
                  ((-H, H), CCW), ((0, 1), CW), ((0, -1), CW)],
}


def _flu(angle_deg: float) -> np.ndarray:
    """A table angle (clockwise from the nose seen from above) as a body-FLU unit vector."""
    a = math.radians(angle_deg)
    return np.array([math.cos(a), -math.sin(a)])


@pytest.mark.parametrize("frame", FRAME_NAMES)
def test_tables_give_the_published_numbering(frame: str) -> None:
    """Each transcribed table puts motor i where the autopilot's documentation does."""
    expected = PUBLISHED[frame.split(":")[1]]
    table = AUTOPILOT_FRAMES[frame]
    assert len(table) == len(expected)
    for i, (rotor, ((x, y), spin)) in enumerate(zip(table, expected, strict=True)):
        np.testing.assert_allclose(_flu(rotor.angle_deg), [x, y], atol=1e-5,
                                   err_msg=f"{frame} motor {i + 1}")
        assert rotor.direction == spin, f"{frame} motor {i + 1}"


def test_every_frame_is_known_for_both_autopilots() -> None:
    assert {n.split(":")[0] for n in FRAME_NAMES} == {"ardupilot", "px4"}
    assert {n.split(":")[1] for n in FRAME_NAMES} == set(PUBLISHED)


def _config(frame: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A config of the frame's rotors, arms and angles a little off, in a shuffled order."""
    expected = PUBLISHED[frame.split(":")[1]]
    shuffle = rng.permutation(len(expected))
    positions, directions = [], []
    for i in shuffle:
        (x, y), spin = expected[i]
        a = math.atan2(y, x) + math.radians(rng.uniform(-8.0, 8.0))
        r = rng.uniform(0.15, 0.3)
        positions.append([r * math.cos(a), r * math.sin(a), rng.uniform(-0.05, 0.05)])
        directions.append(spin)
    return np.array(positions), np.array(directions), shuffle


@pytest.mark.parametrize("frame", FRAME_NAMES)
def test_output_to_rotor_undoes_a_shuffle(frame: str) -> None:
    """Output i maps to the config rotor that was motor i before the shuffle."""
    rng = np.random.default_rng(17)
    for _ in range(5):
        positions, directions, shuffle = _config(frame, rng)
        order = output_to_rotor(positions, directions, frame)
        # Config rotor j is motor shuffle[j]; so motor i is config rotor argsort(shuffle)[i].
        assert order == tuple(int(j) for j in np.argsort(shuffle))


def test_shipped_quad_x_maps_once_its_directions_are_ardupilots() -> None:
    """quad_x lists FL, RL, RR, FR; ArduPilot's motors 1-4 are FR, RL, FL, RR."""
    quad = load_vehicle("quad_x")
    flipped = -quad.rotor_directions
    assert output_to_rotor(quad.rotor_positions, flipped, "ardupilot:quad_x") == (3, 1, 0, 2)
    assert output_to_rotor(quad.rotor_positions, flipped, "px4:quad_x") == (3, 1, 0, 2)


def test_direction_mismatch_is_refused() -> None:
    quad = load_vehicle("quad_x")
    with pytest.raises(MotorOrderError, match=r"motor 1 of ardupilot:quad_x at the front "
                                              r"right \(45°\): counter-clockwise"):
        output_to_rotor(quad.rotor_positions, quad.rotor_directions, "ardupilot:quad_x")


def test_rotor_far_from_every_motor_is_refused() -> None:
    quad = load_vehicle("quad_x")
    positions = quad.rotor_positions.copy()
    positions[0, :2] = [0.0, 0.17]  # front left moved to the left: 90° from the nose
    with pytest.raises(MotorOrderError, match="within 20°"):
        output_to_rotor(positions, -quad.rotor_directions, "ardupilot:quad_x")


def test_rotor_count_and_unknown_frame_are_refused() -> None:
    firefly = load_vehicle("firefly")
    with pytest.raises(MotorOrderError, match="the 4 rotors of px4:quad_x, got 6 rotors"):
        output_to_rotor(firefly.rotor_positions, firefly.rotor_directions, "px4:quad_x")
    with pytest.raises(MotorOrderError, match="one of the known frames"):
        output_to_rotor(firefly.rotor_positions, firefly.rotor_directions, "px4:hexa")


def _with_frame(tmp_path: Path, frame_line: str, flip: bool = True) -> Path:
    quad = load_vehicle("quad_x")
    rotors = tuple(RotorConfig(r.position, -r.direction if flip else r.direction)
                   for r in quad.rotors)
    path = tmp_path / "quad.toml"
    save_vehicle(replace(quad, rotors=rotors), path)
    path.write_text(path.read_text() + f"\n[autopilot]\n{frame_line}\n")
    return path


def test_vehicle_file_names_its_frame_and_round_trips(tmp_path: Path) -> None:
    vehicle = load_vehicle(_with_frame(tmp_path, 'frame = "ardupilot:quad_x"'))
    assert vehicle.autopilot_frame == "ardupilot:quad_x"
    again = tmp_path / "again.toml"
    save_vehicle(vehicle, again)
    assert load_vehicle(again) == replace(vehicle, source=str(again))
    assert load_vehicle("quad_x").autopilot_frame is None


@pytest.mark.parametrize(
    ("line", "flip", "says"),
    [
        ('frame = "ardupilot:quadx"', True, "did you mean 'ardupilot:quad_x'?"),
        ("frame = 4", True, "one of ardupilot:quad_plus, ardupilot:quad_x"),
        ('frame = "ardupilot:quad_x"', False, "[[rotors]][4].direction as motor 1"),
        ('frame = "px4:hexa_x"', True, "the 6 rotors of px4:hexa_x, got 4 rotors"),
        ('type = "quad_x"', True, "[autopilot].type: one of the known keys (frame)"),
    ],
)
def test_bad_autopilot_frame_is_one_line(tmp_path: Path, line: str, flip: bool,
                                         says: str) -> None:
    path = _with_frame(tmp_path, line, flip)
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: [autopilot]")
    assert says in message


def test_shipped_firefly_maps_once_its_directions_are_the_autopilots() -> None:
    """Firefly lists its rotors from 30° (front left) counter-clockwise seen from above."""
    firefly = load_vehicle("firefly")
    with pytest.raises(MotorOrderError, match="direction"):
        output_to_rotor(firefly.rotor_positions, firefly.rotor_directions, "ardupilot:hexa_x")
    # Motors 1-6: right, left, front left, rear right, front right, rear left.
    assert output_to_rotor(firefly.rotor_positions, -firefly.rotor_directions,
                           "ardupilot:hexa_x") == (4, 1, 0, 3, 5, 2)


def _layout(name: str, turn_deg: float = 0.0) -> np.ndarray:
    """PUBLISHED's rotors of a frame, turned ``turn_deg`` about the vertical, as positions."""
    c, s = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))
    return np.array([[0.2 * (c * x - s * y), 0.2 * (s * x + c * y), 0.0]
                     for (x, y), _ in PUBLISHED[name]])


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_frame_ids_select_the_frame_and_name_it(name):
    """FRAME_CLASS/FRAME_TYPE select the ArduPilot frame; the words name both values."""
    from mavsysid.vehicle.motor_order import ARDUPILOT_FRAME_IDS, ardupilot_frame_name

    frame_class, frame_type = ARDUPILOT_FRAME_IDS[f"ardupilot:{name}"]
    found, words = ardupilot_frame_name(frame_class, frame_type)
    assert found == f"ardupilot:{name}"
    kind = {"quad": "Quad", "hexa": "Hexa", "octa": "Octa"}[name.split("_")[0]]
    assert f"({kind})" in words and ("(X)" if name.endswith("_x") else "(Plus)") in words


def test_frames_without_a_motor_table_are_none():
    """An H quad, a BetaFlight order or a Y6 select no frame of the tables."""
    from mavsysid.vehicle.motor_order import ardupilot_frame_name

    for ids, word in (((1, 3), "(H)"), ((1, 12), "(BetaFlight X)"), ((5, 10), "(Y6)")):
        found, words = ardupilot_frame_name(*ids)
        assert found is None and word in words, words


def test_px4_airframe_groups():
    from mavsysid.vehicle.motor_order import px4_airframe_frame

    assert px4_airframe_frame(4001) == "px4:quad_x"
    assert px4_airframe_frame(5001) == "px4:quad_plus"
    assert px4_airframe_frame(6001) == "px4:hexa_x"
    assert px4_airframe_frame(13000) is None  # a VTOL


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_a_layout_matches_its_frame_in_any_order_and_not_turned_45_or_30(name):
    """Shuffled rotors still sit like the frame; turned by half the spacing they do not."""
    from mavsysid.vehicle.motor_order import layout_matches

    rotors = _layout(name)
    rng = np.random.default_rng(3)
    assert layout_matches(rotors[rng.permutation(len(rotors))], f"ardupilot:{name}")
    half = 180.0 / len(rotors)
    assert not layout_matches(_layout(name, half), f"ardupilot:{name}")


def test_mirrors_are_the_rotors_opposite():
    """Quad X: the diagonal; the Firefly: the rotor 180° round; a tricopter has none."""
    from mavsysid.vehicle.motor_order import mirror_rotors

    assert mirror_rotors(_layout("quad_x")) == (1, 0, 3, 2)  # front right ↔ rear left
    firefly = load_vehicle("firefly")
    assert mirror_rotors(firefly.rotor_positions) == (3, 4, 5, 0, 1, 2)
    tri = np.array([[0.2 * math.cos(a), 0.2 * math.sin(a), 0.0]
                    for a in np.radians([0.0, 120.0, 240.0])])
    assert mirror_rotors(tri) == (None, None, None)


def test_output_order_is_the_identity_without_a_frame():
    from mavsysid.vehicle.motor_order import output_order

    config = load_vehicle("sitl_quad")
    assert output_order(config.rotor_positions, config.rotor_directions, None) == (0, 1, 2, 3)
    assert output_order(config.rotor_positions, config.rotor_directions,
                        "ardupilot:quad_x") == (0, 1, 2, 3)
