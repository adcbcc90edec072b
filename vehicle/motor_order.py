"""The autopilots' motor numbering, and its mapping onto a vehicle config's rotor order.

An autopilot log reports its motors by output: ESC i, motor output i (ArduPilot ``ESC``
Instance, ``RCOU`` Ci; PX4 ``esc_status`` esc[i], ``actuator_motors`` control[i],
``actuator_outputs`` output[i]; MAVLink ``ESC_TELEMETRY_*``, ``SERVO_OUTPUT_RAW``). Which
rotor output i drives is the autopilot's frame layout, not the config's rotor order. The
tables below give, for each frame, output i → position and spin direction of its rotor;
`output_to_rotor` matches them to a config's rotors by angle and checks the directions.

Conventions of the tables, as in the sources: the angle is measured from the nose,
**clockwise seen from above** (towards body-FRD +y, the right), degrees; the direction is
mavsysid's ε: +1 counter-clockwise seen from above, −1 clockwise. A config rotor at body
FLU (x, y) (y to the left) has the angle atan2(−y, x).

Sources (transcribed by hand; each autopilot's table kept in its own form):

- ArduPilot, ``libraries/AP_Motors/AP_MotorsMatrix.cpp`` at commit
  0001fe6289822c3be2bb84a13906935adf5993bd, ``setup_motors``: ``add_motor(AP_MOTORS_MOT_i,
  angle, yaw_factor, testing_order)`` for QUAD/HEXA/OCTA × PLUS/X, with
  ``AP_MOTORS_MATRIX_YAW_FACTOR_CW = -1`` and ``_CCW = 1`` (``AP_MotorsMatrix.h``). The angle
  enters as roll factor cos(angle + 90°) = −sin(angle) and pitch factor cos(angle): 45° is
  front right. Current ArduPilot keeps the same numbers in the ``MotorDef`` tables of
  ``setup_quad_matrix``, ``setup_hexa_matrix`` and ``setup_octa_matrix``.
- PX4, the multirotor mixer geometries (``[[rotors]]`` in output order, ``position`` in
  body FRD, ``direction`` "CW"/"CCW", default "CW"): ``src/lib/mixer/geometries/quad_x.toml``
  and ``quad_plus.toml`` at 2b06e3e844ddff872c331cda564435d0fc31b1cb;
  ``src/lib/mixer/MultirotorMixer/geometries/hex_x.toml`` at
  f929353e779a41434625a877d1a9d200f5c16272, ``hex_plus.toml`` at
  b973e271c4cfbb9fd64916db51b5fca573779d84, ``octa_x.toml`` at
  8ab295e86874bd16b8900cb971bda5b28a7b482a, ``octa_plus.toml`` at
  c307a046f9370f7a4016a6eeeaa5ef2a30549eae. PX4 ≥ 1.14 sets the same layouts through
  control allocation (``CA_ROTORn_PX/PY``, ``CA_ROTORn_KM`` > 0 for CCW) in the airframe
  files, rotor n on motor output n + 1. These tables number the motors as ArduPilot's do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mavsysid.vehicle.rotation import wrap_angle

__all__ = [
    "ANGLE_TOLERANCE_DEG",
    "ARDUPILOT_FRAME_IDS",
    "AUTOPILOT_FRAMES",
    "FRAME_NAMES",
    "PX4_AIRFRAME_GROUPS",
    "FrameRotor",
    "MotorOrderError",
    "ardupilot_frame_name",
    "describe_angle",
    "layout_matches",
    "mirror_rotors",
    "output_order",
    "output_to_rotor",
    "px4_airframe_frame",
]

#: How far, degrees, a config rotor may sit from the frame's nominal angle and still match
#: (the nominal frames are regular; real arms are not quite): less than half the 45°
#: spacing of an octocopter, so a match is never ambiguous.
ANGLE_TOLERANCE_DEG = 20.0


@dataclass(frozen=True)
class FrameRotor:
    """The rotor on one motor output of an autopilot frame.

    Attributes
    ----------
    angle_deg : float
        Direction of the rotor from the centre, degrees clockwise from the nose seen from
        above, in (−180, 180].
    direction : int
        +1 counter-clockwise seen from above, −1 clockwise (the paper's ε).
    """

    angle_deg: float
    direction: int


def _ardupilot(*motors: tuple[float, int]) -> tuple[FrameRotor, ...]:
    """ArduPilot's ``add_motor(MOT_i, angle, yaw_factor)`` rows, MOT_1 first."""
    return tuple(FrameRotor(float(a), int(yaw)) for a, yaw in motors)


def _px4(*rotors: tuple[float, float, str]) -> tuple[FrameRotor, ...]:
    """PX4 geometry ``[[rotors]]`` rows (position x, y body FRD; direction), output 1 first."""
    spin = {"CCW": 1, "CW": -1}
    return tuple(FrameRotor(math.degrees(math.atan2(y, x)), spin[d]) for x, y, d in rotors)


_CW, _CCW = -1, 1  # AP_MOTORS_MATRIX_YAW_FACTOR_CW / _CCW
_S, _C = 0.707107, 0.866025  # the sources' rounded sin 45°, cos 30°
_A, _B = 0.9238795, 0.3826834  # cos 22.5°, sin 22.5°

#: Motor output i (0-based) → its rotor, per frame ``"autopilot:frame"``.
AUTOPILOT_FRAMES: dict[str, tuple[FrameRotor, ...]] = {
    "ardupilot:quad_plus": _ardupilot((90, _CCW), (-90, _CCW), (0, _CW), (180, _CW)),
    "ardupilot:quad_x": _ardupilot((45, _CCW), (-135, _CCW), (-45, _CW), (135, _CW)),
    "ardupilot:hexa_plus": _ardupilot((0, _CW), (180, _CCW), (-120, _CW), (60, _CCW),
                                      (-60, _CCW), (120, _CW)),
    "ardupilot:hexa_x": _ardupilot((90, _CW), (-90, _CCW), (-30, _CW), (150, _CCW), (30, _CCW),
                                   (-150, _CW)),
    "ardupilot:octa_plus": _ardupilot((0, _CW), (180, _CW), (45, _CCW), (135, _CCW),
                                      (-45, _CCW), (-135, _CCW), (-90, _CW), (90, _CW)),
    "ardupilot:octa_x": _ardupilot((22.5, _CW), (-157.5, _CW), (67.5, _CCW), (157.5, _CCW),
                                   (-22.5, _CCW), (-112.5, _CCW), (-67.5, _CW), (112.5, _CW)),
    "px4:quad_plus": _px4((0.0, 1.0, "CCW"), (0.0, -1.0, "CCW"), (1.0, 0.0, "CW"),
                          (-1.0, 0.0, "CW")),
    "px4:quad_x": _px4((_S, _S, "CCW"), (-_S, -_S, "CCW"), (_S, -_S, "CW"), (-_S, _S, "CW")),
    "px4:hexa_plus": _px4((1.0, 0.0, "CW"), (-1.0, 0.0, "CCW"), (-0.5, -_C, "CW"),
                          (0.5, _C, "CCW"), (0.5, -_C, "CCW"), (-0.5, _C, "CW")),
    "px4:hexa_x": _px4((0.0, 1.0, "CW"), (0.0, -1.0, "CCW"), (_C, -0.5, "CW"),
                       (-_C, 0.5, "CCW"), (_C, 0.5, "CCW"), (-_C, -0.5, "CW")),
    "px4:octa_plus": _px4((1.0, 0.0, "CW"), (-1.0, 0.0, "CW"), (_S, _S, "CCW"),
                          (-_S, _S, "CCW"), (_S, -_S, "CCW"), (-_S, -_S, "CCW"),
                          (0.0, -1.0, "CW"), (0.0, 1.0, "CW")),
    "px4:octa_x": _px4((_A, _B, "CW"), (-_A, -_B, "CW"), (_B, _A, "CCW"), (-_A, _B, "CCW"),
                       (_A, -_B, "CCW"), (-_B, -_A, "CCW"), (_B, -_A, "CW"), (-_B, _A, "CW")),
}

#: The frame names a vehicle file may give as ``[autopilot] frame``.
FRAME_NAMES: tuple[str, ...] = tuple(AUTOPILOT_FRAMES)

#: ArduPilot's FRAME_CLASS and FRAME_TYPE of each of its frames above (``AP_Motors_Class.h``:
#: motor_frame_class QUAD 1, HEXA 2, OCTA 3; motor_frame_type PLUS 0, X 1).
ARDUPILOT_FRAME_IDS: dict[str, tuple[int, int]] = {
    "ardupilot:quad_plus": (1, 0), "ardupilot:quad_x": (1, 1),
    "ardupilot:hexa_plus": (2, 0), "ardupilot:hexa_x": (2, 1),
    "ardupilot:octa_plus": (3, 0), "ardupilot:octa_x": (3, 1),
}
#: ArduPilot's names of FRAME_CLASS and FRAME_TYPE values, for messages
#: (``libraries/AP_Motors/AP_Motors_Class.h``, enums motor_frame_class and motor_frame_type).
_ARDUPILOT_CLASSES = {0: "Undefined", 1: "Quad", 2: "Hexa", 3: "Octa", 4: "OctaQuad", 5: "Y6",
                      6: "Heli", 7: "Tri", 8: "SingleCopter", 9: "CoaxCopter", 10: "Tailsitter",
                      11: "Heli_Dual", 12: "DodecaHexa", 13: "HeliQuad", 14: "Deca"}
_ARDUPILOT_TYPES = {0: "Plus", 1: "X", 2: "V", 3: "H", 4: "V-Tail", 5: "A-Tail",
                    6: "Plus reversed", 10: "Y6B", 11: "Y6F", 12: "BetaFlight X", 13: "DJI X",
                    14: "clockwise X", 15: "I", 16: "Plus, no yaw torque",
                    17: "X, no yaw torque", 18: "BetaFlight X reversed", 19: "Y4"}
#: PX4's airframe groups by SYS_AUTOSTART thousands (``ROMFS/px4fmu_common/init.d/airframes``:
#: 4xxx quadrotor x, 5xxx quadrotor +, 6xxx hexarotor x, 7xxx hexarotor +, 8xxx octorotor
#: x, 9xxx octorotor +); within a group the motor order is the group's mixer geometry.
PX4_AIRFRAME_GROUPS: dict[int, str] = {4: "px4:quad_x", 5: "px4:quad_plus", 6: "px4:hexa_x",
                                       7: "px4:hexa_plus", 8: "px4:octa_x", 9: "px4:octa_plus"}


def ardupilot_frame_name(frame_class: int, frame_type: int) -> tuple[str | None, str]:
    """The frame of `AUTOPILOT_FRAMES` that ArduPilot's FRAME_CLASS and FRAME_TYPE select.

    Parameters
    ----------
    frame_class, frame_type : int
        The parameters' values.

    Returns
    -------
    name : str or None
        ``"ardupilot:quad_x"`` and so on; None for a frame those tables do not hold (a Y6,
        an H quad, a BetaFlight motor order, …).
    words : str
        The parameters with ArduPilot's names of their values, for messages:
        ``"FRAME_CLASS 1 (Quad), FRAME_TYPE 0 (Plus)"``.
    """
    words = (f"FRAME_CLASS {frame_class} ({_ARDUPILOT_CLASSES.get(frame_class, '?')}), "
             f"FRAME_TYPE {frame_type} ({_ARDUPILOT_TYPES.get(frame_type, '?')})")
    wanted = (int(frame_class), int(frame_type))
    name = next((n for n, ids in ARDUPILOT_FRAME_IDS.items() if ids == wanted), None)
    return name, words


def px4_airframe_frame(sys_autostart: int) -> str | None:
    """The frame of `AUTOPILOT_FRAMES` of a PX4 airframe (its SYS_AUTOSTART), or None.

    Parameters
    ----------
    sys_autostart : int
        The airframe's SYS_AUTOSTART; its thousands name the group (`PX4_AIRFRAME_GROUPS`).
    """
    return PX4_AIRFRAME_GROUPS.get(int(sys_autostart) // 1000)

_SECTORS = ("front", "front right", "right", "rear right", "rear", "rear left", "left",
            "front left")


class MotorOrderError(ValueError):
    """A config's rotors do not match an autopilot frame: what was expected, what was found.

    Parameters
    ----------
    expected : str
        What the frame requires.
    found : str
        What the config has.
    """

    def __init__(self, expected: str, found: str) -> None:
        super().__init__(f"{expected}, got {found}")
        self.expected = expected
        self.found = found


def describe_angle(angle_deg: float) -> str:
    """A position for messages: ``"front right (45°)"``, angle clockwise from the nose.

    Parameters
    ----------
    angle_deg : float
        Clockwise from the nose, degrees.
    """
    sector = _SECTORS[round(angle_deg / 45.0) % 8]
    return f"{sector} ({angle_deg:g}°)"


def _spin(direction: int) -> str:
    return f"{'counter-clockwise' if direction > 0 else 'clockwise'} ({direction:+d})"


def _angle_gap(a: float, b: float) -> float:
    """|a − b| in degrees, wrapped into [0, 180]."""
    return abs(math.degrees(wrap_angle(math.radians(a - b))))


def output_to_rotor(positions: np.ndarray, directions: np.ndarray,
                    frame: str) -> tuple[int, ...]:
    """Which config rotor each motor output of an autopilot frame drives.

    Parameters
    ----------
    positions : ndarray, shape (k, 3)
        The config's rotor positions, m, body FLU.
    directions : ndarray, shape (k,)
        Their spin directions ε, ±1.
    frame : str
        A name of `FRAME_NAMES`, e.g. ``"ardupilot:quad_x"``.

    Returns
    -------
    tuple of int, length k
        Element i is the 0-based config rotor index of motor output i (output i + 1 in
        the autopilot's 1-based numbering): ``speeds_config[:, order[i]] = outputs[:, i]``.

    Raises
    ------
    MotorOrderError
        An unknown frame, another rotor count, a rotor on the centre, a rotor farther than
        `ANGLE_TOLERANCE_DEG` from every output's angle, two outputs on one rotor, or a
        spin direction that differs from the frame's.
    """
    if frame not in AUTOPILOT_FRAMES:
        raise MotorOrderError(f"one of the known frames ({', '.join(FRAME_NAMES)})",
                              f"{frame!r}")
    layout = AUTOPILOT_FRAMES[frame]
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    if positions.shape[0] != len(layout):
        raise MotorOrderError(f"a vehicle with the {len(layout)} rotors of {frame}",
                              f"{positions.shape[0]} rotors")
    radius = np.hypot(positions[:, 0], positions[:, 1])
    if (radius < 1e-9).any():
        raise MotorOrderError(f"rotors off the centre, at an angle that names a {frame} motor",
                              f"[[rotors]][{int(np.argmax(radius < 1e-9)) + 1}] at x = y = 0")
    angles = np.degrees(np.arctan2(-positions[:, 1], positions[:, 0]))
    order: list[int] = []
    for i, rotor in enumerate(layout):
        gaps = [_angle_gap(rotor.angle_deg, a) for a in angles]
        j = int(np.argmin(gaps))
        where = f"motor {i + 1} of {frame} at the {describe_angle(rotor.angle_deg)}"
        if gaps[j] > ANGLE_TOLERANCE_DEG or j in order:
            raise MotorOrderError(
                f"a rotor within {ANGLE_TOLERANCE_DEG:g}° of {where}, clockwise from the nose "
                "seen from above",
                f"the nearest, [[rotors]][{j + 1}], at the {describe_angle(round(angles[j], 1))}"
                + (", already matched to another motor" if j in order else ""))
        if int(directions[j]) != rotor.direction:
            raise MotorOrderError(
                f"[[rotors]][{j + 1}].direction as {where}: {_spin(rotor.direction)}",
                f"{_spin(int(directions[j]))}")
        order.append(j)
    return tuple(order)


def _angles(positions: np.ndarray) -> np.ndarray:
    """Rotor directions from the centre, degrees clockwise from the nose (body FLU in)."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    return np.degrees(np.arctan2(-positions[:, 1], positions[:, 0]))


def layout_matches(positions: np.ndarray, frame: str) -> bool:
    """Whether the rotors sit at the angles of ``frame``'s rotors, in any order.

    Spin directions and numbering are not compared: this tells a "+" layout from an "X"
    one (rotors 45° apart) whatever order the rotors are listed in.

    Parameters
    ----------
    positions : ndarray, shape (k, 3)
        Rotor positions, m, body FLU.
    frame : str
        A name of `FRAME_NAMES`.
    """
    layout = AUTOPILOT_FRAMES[frame]
    angles = list(_angles(positions))
    if len(angles) != len(layout):
        return False
    for rotor in layout:
        gaps = [_angle_gap(rotor.angle_deg, a) for a in angles]
        j = int(np.argmin(gaps))
        if gaps[j] > ANGLE_TOLERANCE_DEG:
            return False
        angles.pop(j)
    return True


def output_order(positions: np.ndarray, directions: np.ndarray,
                 frame: str | None) -> tuple[int, ...]:
    """`output_to_rotor` for a vehicle's ``[autopilot] frame``; output i is rotor i when None.

    Parameters
    ----------
    positions : ndarray, shape (k, 3)
        The config's rotor positions, m, body FLU.
    directions : ndarray, shape (k,)
        Their spin directions ε, ±1.
    frame : str or None
        The config's ``autopilot_frame``.
    """
    if frame is None:
        return tuple(range(np.asarray(directions).size))
    return output_to_rotor(positions, directions, frame)


def mirror_rotors(positions: np.ndarray) -> tuple[int | None, ...]:
    """Each rotor's mirror: the rotor opposite it through the centre, or None.

    The allocation pairs opposite rotors: in hover each carries what its mirror carries,
    so a motor working much harder than its mirror is weak, or the centre of gravity is
    off towards it.

    Parameters
    ----------
    positions : ndarray, shape (k, 3)
        Rotor positions, m, body FLU.

    Returns
    -------
    tuple of int or None, length k
        Element i is the index of the rotor within `ANGLE_TOLERANCE_DEG` of 180° from
        rotor i (None when there is none, as on a tricopter).
    """
    angles = _angles(positions)
    out: list[int | None] = []
    for i, a in enumerate(angles):
        gaps = [_angle_gap(a + 180.0, b) if j != i else math.inf for j, b in enumerate(angles)]
        j = int(np.argmin(gaps))
        out.append(j if gaps[j] <= ANGLE_TOLERANCE_DEG else None)
    return tuple(out)
