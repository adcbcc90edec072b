"""Validation of vehicle TOML documents against the schema of docs/architecture.md.

Validation runs in two phases. `validate_document` checks the parsed TOML key by key
(unknown keys, missing keys, types, signs) and returns plain, normalised values;
`mavsysid.vehicle.config_checks.check_vehicle` then checks what only the assembled
`VehicleConfig` can tell (inertia consistency, a c_M that is really a ratio, rotor
allocation rank, lift, limit order).

Every problem, here and in `check_vehicle`, raises `ConfigError` with one line
``"<file>: <key>: <expected>, got <found>"`` (`raise_config_error`), keys spelled
``mass``, ``[parameters].c_M``, ``[[rotors]][3].direction``, ``[effects.motor_lag].tau``.

Known model effects are optional tables ``[effects.NAME]`` (NAME from
`mavsysid.vehicle.model_effects.EFFECTS`) of the effect's parameters in SI units; a parameter
left out is 0.

The optional ``[autopilot]`` table names the autopilot frame whose motor outputs the
rotors are (``frame = "ardupilot:quad_x"``, a name of
`mavsysid.vehicle.motor_order.FRAME_NAMES`); the rotors must then match that frame's
layout in angle and spin direction (`mavsysid.vehicle.motor_order.output_to_rotor`).

The optional ``[flight]`` table holds ``box = [x_min, y_min, z_min, x_max, y_max, z_max]``
(m, world ENU, each min below its max): where the vehicle may be flown.

The optional ``[imu]`` table holds ``position = [x, y, z]`` (m, body FLU): the IMU's
offset from the centre of gravity.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any, NoReturn

from mavsysid.vehicle.config_types import ALLOCATION_MODES, PARAMETER_UNITS
from mavsysid.vehicle.model_effects import EFFECTS
from mavsysid.vehicle.motor_order import FRAME_NAMES, MotorOrderError, output_to_rotor

from mavsysid.errors import ConfigError

__all__ = ["EFFECT_PARAMETER_SIGNS", "MIN_ROTORS", "describe_value", "raise_config_error",
           "validate_document"]

#: Fewer rotors than this cannot control thrust, roll, pitch and yaw independently.
MIN_ROTORS = 4


#: Longest value shown in a message, characters.
_MAX_SHOWN = 60


def raise_config_error(file: str, key: str, expected: str, found: str) -> NoReturn:
    """Raise the one-line ConfigError of the module docstring.

    Parameters
    ----------
    file : str
        The vehicle file (as the user named it).
    key : str
        The key, spelled as in the module docstring.
    expected : str
        What the key must hold (with its unit).
    found : str
        What it holds (`describe_value`).
    """
    message = f"{file}: {key}: {expected}, got {found}"
    # One line is part of the CLI contract (exit 2, one-line message).
    raise ConfigError(" ".join(message.split()))


def describe_value(value: Any) -> str:
    """A short, one-line description of a TOML value for error messages.

    Parameters
    ----------
    value : Any
        A parsed TOML value.
    """
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, str):
        shown = value if len(value) <= _MAX_SHOWN else value[:_MAX_SHOWN] + "…"
        return f"a string {shown!r}"
    if isinstance(value, Mapping):
        return "a table"
    if isinstance(value, list):
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
            text = "[" + ", ".join(repr(v) for v in value) + "]"
            if len(text) <= _MAX_SHOWN:
                return text
        return f"an array of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, int | float):
        return repr(value)
    return f"a {type(value).__name__} ({value})"

# (key, unit, sign) per optional/required key of each table; sign is "positive" or
# "nonnegative". Units go into messages so a user sees what scale is expected.
_PARAMETERS: dict[str, tuple[str, str]] = {
    "c_T": (PARAMETER_UNITS["c_T"], "positive"),
    "c_D": (PARAMETER_UNITS["c_D"], "nonnegative"),
    "c_M": (PARAMETER_UNITS["c_M"], "positive"),
    "J": (PARAMETER_UNITS["j_x"], "positive"),
}
_LIMITS: dict[str, tuple[str, str]] = {
    "rotor_speed_max": ("rad/s", "positive"),
    "rotor_speed_min": ("rad/s", "nonnegative"),
    "thrust_min_ratio": ("× m g", "positive"),
    "thrust_max_ratio": ("× m g", "positive"),
    "body_rate_max": ("rad/s", "positive"),
    "yaw_acceleration_max": ("rad/s²", "positive"),
    "speed_max": ("m/s", "positive"),
    "segment_time_max": ("s", "positive"),
    "allocation": (" or ".join(f'"{m}"' for m in ALLOCATION_MODES), "choice"),
}
_MOTOR: dict[str, tuple[str, str]] = {
    "time_constant": ("s", "nonnegative"),
    "pwm_min": ("µs", "nonnegative"),
    "pwm_max": ("µs", "positive"),
    "thrust_expo": ("between 0 and 1", "nonnegative"),
    "voltage": ("V", "nonnegative"),
    "curve_sigma": ("relative", "nonnegative"),
}
_NOISE: dict[str, tuple[str, str]] = {
    "position_sigma": ("m", "nonnegative"),
    "attitude_sigma": ("rad", "nonnegative"),
    "rotor_speed_sigma": ("rad/s", "nonnegative"),
    "force_density": ("N·√s", "nonnegative"),
    "moment_density": ("N·m·√s", "nonnegative"),
    "gyro_sigma": ("rad/s", "nonnegative"),
    "accel_sigma": ("m/s²", "nonnegative"),
    "gyro_bias_sigma": ("rad/s", "nonnegative"),
    "accel_bias_sigma": ("m/s²", "nonnegative"),
}
_TABLES: dict[str, dict[str, tuple[str, str]]] = {
    "parameters": _PARAMETERS,
    "limits": _LIMITS,
    "motor": _MOTOR,
    "noise": _NOISE,
}
_REQUIRED: dict[str, tuple[str, ...]] = {
    "parameters": ("c_T", "c_D", "c_M", "J"),
    "limits": ("rotor_speed_max",),
    "motor": (),
    "noise": (),
}
_VECTOR_KEYS = frozenset({"J"})
_ROTOR_KEYS = ("position", "direction")
# Top-level keys and how they are spelled in messages.
_TOP_LEVEL: dict[str, str] = {
    "name": "name",
    "description": "description",
    "mass": "mass",
    "rotors": "[[rotors]]",
    "parameters": "[parameters]",
    "limits": "[limits]",
    "motor": "[motor]",
    "noise": "[noise]",
    "effects": "[effects]",
    "autopilot": "[autopilot]",
    "flight": "[flight]",
    "imu": "[imu]",
}
#: Parameters of effects that have a sign by their meaning, ``(effect, parameter) →
#: "positive" | "nonnegative"``; the rest may be negative. Read by the effect fits too.
EFFECT_PARAMETER_SIGNS: dict[tuple[str, str], str] = {
    (effect.name, p.name): p.sign for effect in EFFECTS.values() for p in effect.parameters
    if p.sign is not None}


def _suggestion(key: str, section: str | None, index: int | None = None) -> str:
    """A "did you mean …?" hint for an unknown key, or an empty string."""
    local = list(_TOP_LEVEL) if section is None else list(_TABLES.get(section, _ROTOR_KEYS))
    folded = {k.lower(): k for k in local}
    if key.lower() in folded:
        match = folded[key.lower()]
        return f" (did you mean {_spell(section, match, index)}?)"
    # A key put into the wrong table is a common slip: point at where it belongs.
    for table, spec in _TABLES.items():
        if table != section and key in spec:
            return f" (did you mean [{table}].{key}?)"
    if section != "rotors" and key in _ROTOR_KEYS:
        return f" (did you mean [[rotors]][i].{key}?)"
    close = difflib.get_close_matches(key, local, n=1, cutoff=0.6)
    return f" (did you mean {_spell(section, close[0], index)}?)" if close else ""


def _spell(section: str | None, key: str, index: int | None = None) -> str:
    """Spell a key as in messages: ``mass``, ``[limits].speed_max``, ``[[rotors]][2].x``."""
    if section is None:
        return _TOP_LEVEL.get(key, key)
    if section == "rotors":
        return f"[[rotors]][{index}].{key}" if index is not None else f"[[rotors]].{key}"
    return f"[{section}].{key}"


def _check_known(
    file: str, table: Mapping[str, Any], section: str | None, index: int | None = None
) -> None:
    """Reject keys not in the schema, suggesting the closest known key."""
    allowed = _TOP_LEVEL if section is None else _TABLES.get(section, dict.fromkeys(_ROTOR_KEYS))
    for key, value in table.items():
        if key in allowed:
            continue
        if section is None and isinstance(value, Mapping):
            spelled = f"[{key}]"
        elif section is None and isinstance(value, list) and value and all(
            isinstance(v, Mapping) for v in value
        ):
            spelled = f"[[{key}]]"
        else:
            spelled = _spell(section, key, index)
        known = ", ".join(_spell(section, k) if section is None else k for k in allowed)
        raise_config_error(file, spelled, f"one of the known keys ({known})",
                           f"an unknown key{_suggestion(key, section, index)}")


def _number(file: str, key: str, value: Any, unit: str, sign: str | None) -> float:
    """Validate one finite number with an optional sign constraint; ints are accepted."""
    # bool is an int subclass in Python, but `mass = true` is never meant as 1 kg.
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise_config_error(file, key, f"a number ({unit})", describe_value(value))
    number = float(value)
    if not math.isfinite(number):
        raise_config_error(file, key, f"a finite number ({unit})", describe_value(value))
    if sign == "positive" and number <= 0.0:
        raise_config_error(file, key, f"a positive number ({unit})", describe_value(value))
    if sign == "nonnegative" and number < 0.0:
        raise_config_error(file, key, f"a number ≥ 0 ({unit})", describe_value(value))
    return number


def _vector3(file: str, key: str, value: Any, unit: str, sign: str | None) -> tuple[float, ...]:
    """Validate an array of exactly three finite numbers with an optional sign constraint."""
    what = {"positive": "positive ", "nonnegative": "non-negative "}.get(sign or "", "")
    expected = f"an array of 3 {what}finite numbers ({unit})"
    if not isinstance(value, list) or len(value) != 3:
        raise_config_error(file, key, expected, describe_value(value))
    numbers = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, int | float):
            raise_config_error(file, key, expected,
                               f"{describe_value(value)} containing {describe_value(item)}")
        numbers.append(float(item))
    bad = [
        not math.isfinite(v) or (sign == "positive" and v <= 0) or (sign == "nonnegative" and v < 0)
        for v in numbers
    ]
    if any(bad):
        raise_config_error(file, key, expected, describe_value(value))
    return tuple(numbers)


def _table(file: str, doc: Mapping[str, Any], section: str) -> dict[str, Any]:
    """Validate one of the flat tables ([parameters], [limits], [motor], [noise])."""
    spec = _TABLES[section]
    required = _REQUIRED[section]
    raw = doc.get(section)
    if raw is None:
        if required:
            raise_config_error(file, f"[{section}]", f"a table with {', '.join(required)}",
                               "nothing (the table is missing)")
        return {}
    if not isinstance(raw, Mapping):
        raise_config_error(file, f"[{section}]", "a table", describe_value(raw))
    _check_known(file, raw, section)
    values: dict[str, Any] = {}
    for key, (unit, sign) in spec.items():
        spelled = _spell(section, key)
        if key not in raw:
            if key in required:
                kind = "an array of 3 numbers" if key in _VECTOR_KEYS else "a number"
                raise_config_error(file, spelled, f"{kind} ({unit})",
                                   "nothing (the key is missing)")
            continue
        if sign == "choice":  # [limits].allocation, the one string of these tables
            if raw[key] not in ALLOCATION_MODES:
                raise_config_error(file, spelled, unit, describe_value(raw[key]))
            values[key] = raw[key]
            continue
        check = _vector3 if key in _VECTOR_KEYS else _number
        values[key] = check(file, spelled, raw[key], unit, sign)
    return values


def _rotors(file: str, doc: Mapping[str, Any]) -> list[tuple[tuple[float, ...], int]]:
    """Validate the [[rotors]] array: at least `MIN_ROTORS` tables of position, direction."""
    raw = doc.get("rotors")
    expected = f"an array of at least {MIN_ROTORS} [[rotors]] tables"
    if raw is None:
        raise_config_error(file, "[[rotors]]", expected, "nothing (the key is missing)")
    if not isinstance(raw, list) or not all(isinstance(r, Mapping) for r in raw):
        found = describe_value(raw)
        # A bare number here is most likely a rotor count, not a rotor list.
        if isinstance(raw, int | float) and not isinstance(raw, bool):
            found = f"the number {found}"
        raise_config_error(file, "[[rotors]]", expected, found)
    if len(raw) < MIN_ROTORS:
        raise_config_error(file, "[[rotors]]", expected,
                           f"{len(raw)} rotor{'s' if len(raw) != 1 else ''}")
    rotors = []
    for index, rotor in enumerate(raw, start=1):
        _check_known(file, rotor, "rotors", index)
        for key in _ROTOR_KEYS:
            if key not in rotor:
                what = "an array of 3 numbers (m, body FLU)" if key == "position" else "+1 or -1"
                raise_config_error(file, _spell("rotors", key, index), what,
                                   "nothing (the key is missing)")
        position = _vector3(
            file, _spell("rotors", "position", index), rotor["position"], "m, body FLU", None
        )
        direction = rotor["direction"]
        # ±1.0 is harmless, but 0, 2 or true are not a spin direction.
        if isinstance(direction, bool) or direction not in (1, -1):
            raise_config_error(
                file, _spell("rotors", "direction", index),
                "+1 (counter-clockwise from above) or -1 (clockwise)", describe_value(direction))
        rotors.append((position, int(direction)))
    return rotors


def _unknown_name(file: str, spelled: str, name: str, known: list[str], what: str,
                  spell) -> NoReturn:
    """Reject an unknown effect or effect parameter, suggesting the closest known one."""
    folded = {k.lower(): k for k in known}
    close = ([folded[name.lower()]] if name.lower() in folded
             else difflib.get_close_matches(name, known, n=1, cutoff=0.6))
    hint = f" (did you mean {spell(close[0])}?)" if close else ""
    raise_config_error(file, spelled, f"one of the known {what}s ({', '.join(known)})",
                       f"an unknown {what}{hint}")


def _effects(file: str, doc: Mapping[str, Any]) -> list[tuple[str, dict[str, float]]]:
    """Validate the optional ``[effects.NAME]`` tables: known names, keys and numbers."""
    raw = doc.get("effects")
    if raw is None:
        return []
    if not isinstance(raw, Mapping):
        raise_config_error(file, "[effects]", "a table of [effects.NAME] tables",
                           describe_value(raw))
    out = []
    for name, table in raw.items():
        if name not in EFFECTS:
            _unknown_name(file, f"[effects.{name}]", name, list(EFFECTS), "effect",
                          lambda n: f"[effects.{n}]")
        if not isinstance(table, Mapping):
            raise_config_error(file, f"[effects.{name}]", "a table of the effect's parameters",
                               describe_value(table))
        parameters = {p.name: p for p in EFFECTS[name].parameters}
        values = {}
        for key, value in table.items():
            spelled = f"[effects.{name}].{key}"
            if key not in parameters:
                _unknown_name(file, spelled, key, list(parameters), "key",
                              lambda k, n=name: f"[effects.{n}].{k}")
            values[key] = _number(file, spelled, value, parameters[key].unit,
                                  EFFECT_PARAMETER_SIGNS.get((name, key)))
        out.append((name, values))
    return out


def _autopilot_frame(file: str, doc: Mapping[str, Any],
                     rotors: list[tuple[tuple[float, ...], int]]) -> str | None:
    """Validate the optional ``[autopilot]`` table: a known frame the rotors match."""
    raw = doc.get("autopilot")
    if raw is None:
        return None
    if not isinstance(raw, Mapping):
        raise_config_error(file, "[autopilot]", "a table with frame = \"AUTOPILOT:FRAME\"",
                           describe_value(raw))
    for key in raw:
        if key != "frame":
            raise_config_error(file, f"[autopilot].{key}", "one of the known keys (frame)",
                               "an unknown key")
    frame = raw.get("frame")
    if frame is None:
        raise_config_error(file, "[autopilot].frame", f"one of {', '.join(FRAME_NAMES)}",
                           "nothing (the key is missing)")
    if not isinstance(frame, str) or frame not in FRAME_NAMES:
        close = difflib.get_close_matches(str(frame), FRAME_NAMES, n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise_config_error(file, "[autopilot].frame", f"one of {', '.join(FRAME_NAMES)}",
                           f"{describe_value(frame)}{hint}")
    try:
        output_to_rotor([p for p, _ in rotors], [d for _, d in rotors], frame)
    except MotorOrderError as exc:
        raise_config_error(file, "[autopilot].frame", f"rotors laid out as {frame}: "
                           f"{exc.expected}", exc.found)
    return frame


def _flight_box(file: str, doc: Mapping[str, Any]) -> tuple[float, ...] | None:
    """Validate the optional ``[flight]`` table: ``box``, six numbers, each min < max."""
    raw = doc.get("flight")
    if raw is None:
        return None
    expected = "[x_min, y_min, z_min, x_max, y_max, z_max] (m), each min below its max"
    if not isinstance(raw, Mapping) or set(raw) != {"box"}:
        raise_config_error(file, "[flight]", "a table with only box = " + expected,
                           describe_value(raw))
    box = raw["box"]
    if not isinstance(box, list) or len(box) != 6:
        raise_config_error(file, "[flight].box", expected, describe_value(box))
    values = [_number(file, "[flight].box", v, "m", None) for v in box]
    if any(lo >= hi for lo, hi in zip(values[:3], values[3:], strict=True)):
        raise_config_error(file, "[flight].box", expected, describe_value(box))
    return tuple(values)


def _imu_position(file: str, doc: Mapping[str, Any]) -> tuple[float, ...] | None:
    """Validate the optional ``[imu]`` table: ``position``, three numbers (m, body FLU)."""
    raw = doc.get("imu")
    if raw is None:
        return None
    if not isinstance(raw, Mapping) or set(raw) != {"position"}:
        raise_config_error(file, "[imu]", "a table with only position = [x, y, z] (m, body "
                           "FLU, from the centre of gravity)", describe_value(raw))
    return _vector3(file, "[imu].position", raw["position"], "m, body FLU", None)


def validate_document(file: str, doc: Mapping[str, Any]) -> dict[str, Any]:
    """Check a parsed TOML document key by key and return normalised values.

    Parameters
    ----------
    file : str
        How the file is named in error messages.
    doc : mapping
        The document as returned by `tomllib`.

    Returns
    -------
    dict
        ``name`` (str or None), ``mass`` (float, kg), ``rotors`` (list of
        (position tuple in m, direction int)), and ``parameters``, ``limits``, ``motor``,
        ``noise``: dicts holding only the keys present in the file, as floats (``J`` a
        tuple of 3 floats; ``[limits].allocation`` a string of `ALLOCATION_MODES`);
        ``effects``: list of (effect name, {parameter: float}) in
        file order; ``autopilot_frame``: the ``[autopilot] frame`` name or None;
        ``box``: the ``[flight] box`` (6 floats, m) or None; ``imu_position``: the
        ``[imu] position`` (3 floats, m) or None.

    Raises
    ------
    ConfigError
        On the first problem found.
    """
    # Unknown keys first: a typo such as `mas = 1.5` should be reported as a typo,
    # not as a missing `mass`.
    _check_known(file, doc, None)
    for key in ("name", "description"):
        if key in doc and not (isinstance(doc[key], str) and doc[key].strip()):
            raise_config_error(file, key, "a non-empty string", describe_value(doc[key]))
    if "mass" not in doc:
        raise_config_error(file, "mass", "a number (kg)", "nothing (the key is missing)")
    mass = _number(file, "mass", doc["mass"], "kg", "positive")
    rotors = _rotors(file, doc)
    tables = {section: _table(file, doc, section) for section in _TABLES}
    return {"name": doc.get("name"), "mass": mass, "rotors": rotors, **tables,
            "effects": _effects(file, doc),
            "autopilot_frame": _autopilot_frame(file, doc, rotors),
            "box": _flight_box(file, doc), "imu_position": _imu_position(file, doc)}
