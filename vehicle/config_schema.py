"""Validation of vehicle TOML documents against the schema of docs/architecture.md.

Validation runs in two phases. `validate_document` checks the parsed TOML key by key
(unknown keys, missing keys, types, signs) and returns plain, normalised values;
`check_vehicle` then checks what only the assembled `VehicleConfig` can tell (inertia
consistency, a c_M that is really a ratio, rotor allocation rank, lift, limit order).

Every problem raises `ConfigError` with one line ``"<file>: <key>: <expected>, got
<found>"``, keys spelled ``mass``, ``[parameters].c_M``, ``[[rotors]][3].direction``,
``[effects.motor_lag].tau``.

Known model effects are optional tables ``[effects.NAME]`` (NAME from
`mavsysid.vehicle.model_effects.EFFECTS`) of the effect's parameters in SI units; a parameter
left out is 0.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.model_effects import EFFECTS

from mavsysid.errors import ConfigError

if TYPE_CHECKING:
    from mavsysid.vehicle.config import VehicleConfig

__all__ = ["MIN_ROTORS", "check_vehicle", "validate_document"]

#: Fewer rotors than this cannot control thrust, roll, pitch and yaw independently.
MIN_ROTORS = 4

# (key, unit, sign) per optional/required key of each table; sign is "positive" or
# "nonnegative". Units go into messages so a user sees what scale is expected.
_PARAMETERS: dict[str, tuple[str, str]] = {
    "c_T": ("N/(rad/s)²", "positive"),
    "c_D": ("s/m", "nonnegative"),
    "c_M": ("N·m/(rad/s)²", "positive"),
    "J": ("kg·m²", "positive"),
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
}
_MOTOR: dict[str, tuple[str, str]] = {
    "time_constant": ("s", "nonnegative"),
    "pwm_min": ("µs", "nonnegative"),
    "pwm_max": ("µs", "positive"),
    "thrust_expo": ("between 0 and 1", "nonnegative"),
}
_NOISE: dict[str, tuple[str, str]] = {
    "position_sigma": ("m", "nonnegative"),
    "attitude_sigma": ("rad", "nonnegative"),
    "rotor_speed_sigma": ("rad/s", "nonnegative"),
    "force_density": ("N·√s", "nonnegative"),
    "moment_density": ("N·m·√s", "nonnegative"),
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
}
# Parameters of effects that have a sign by their meaning (the rest may be negative).
_EFFECT_SIGNS: dict[tuple[str, str], str] = {
    ("motor_lag", "tau"): "nonnegative",
    ("ground_effect", "rotor_radius"): "positive",
    ("body_drag", "k"): "nonnegative",
    ("rotor_drag_linear", "k"): "nonnegative",
}

# The RotorS Firefly inertia (the reference vehicle of docs/architecture.md) has j_z 21 % above
# j_x + j_y, which no rigid body can have. Tolerating that much keeps the reference
# loadable while still catching decimal-point slips and swapped units (factors ≥ 10).
_INERTIA_TRIANGLE_SLACK = 0.25
# c_M/c_T is the rotor's torque-to-thrust lever, a few cm on any real propeller;
# RotorS's ratio (≈ 0.016 m for the Firefly) passed as c_M gives a value ≥ 1000 m.
_MAX_MOMENT_ARM = 0.1
# Relative singular-value threshold below which an allocation direction is missing.
_RANK_RTOL = 1e-9
_MAX_SHOWN = 60


def _fail(file: str, key: str, expected: str, found: str) -> NoReturn:
    """Raise the one-line ConfigError of the module docstring."""
    message = f"{file}: {key}: {expected}, got {found}"
    # One line is part of the CLI contract (exit 2, one-line message).
    raise ConfigError(" ".join(message.split()))


def _describe(value: Any) -> str:
    """A short, one-line description of a TOML value for error messages."""
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
        _fail(file, spelled, f"one of the known keys ({known})",
              f"an unknown key{_suggestion(key, section, index)}")


def _number(file: str, key: str, value: Any, unit: str, sign: str | None) -> float:
    """Validate one finite number with an optional sign constraint; ints are accepted."""
    # bool is an int subclass in Python, but `mass = true` is never meant as 1 kg.
    if isinstance(value, bool) or not isinstance(value, int | float):
        _fail(file, key, f"a number ({unit})", _describe(value))
    number = float(value)
    if not math.isfinite(number):
        _fail(file, key, f"a finite number ({unit})", _describe(value))
    if sign == "positive" and number <= 0.0:
        _fail(file, key, f"a positive number ({unit})", _describe(value))
    if sign == "nonnegative" and number < 0.0:
        _fail(file, key, f"a number ≥ 0 ({unit})", _describe(value))
    return number


def _vector3(file: str, key: str, value: Any, unit: str, sign: str | None) -> tuple[float, ...]:
    """Validate an array of exactly three finite numbers with an optional sign constraint."""
    what = {"positive": "positive ", "nonnegative": "non-negative "}.get(sign or "", "")
    expected = f"an array of 3 {what}finite numbers ({unit})"
    if not isinstance(value, list) or len(value) != 3:
        _fail(file, key, expected, _describe(value))
    numbers = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, int | float):
            _fail(file, key, expected, f"{_describe(value)} containing {_describe(item)}")
        numbers.append(float(item))
    bad = [
        not math.isfinite(v) or (sign == "positive" and v <= 0) or (sign == "nonnegative" and v < 0)
        for v in numbers
    ]
    if any(bad):
        _fail(file, key, expected, _describe(value))
    return tuple(numbers)


def _table(file: str, doc: Mapping[str, Any], section: str) -> dict[str, Any]:
    """Validate one of the flat tables ([parameters], [limits], [motor], [noise])."""
    spec = _TABLES[section]
    required = _REQUIRED[section]
    raw = doc.get(section)
    if raw is None:
        if required:
            _fail(file, f"[{section}]", f"a table with {', '.join(required)}",
                  "nothing (the table is missing)")
        return {}
    if not isinstance(raw, Mapping):
        _fail(file, f"[{section}]", "a table", _describe(raw))
    _check_known(file, raw, section)
    values: dict[str, Any] = {}
    for key, (unit, sign) in spec.items():
        spelled = _spell(section, key)
        if key not in raw:
            if key in required:
                kind = "an array of 3 numbers" if key in _VECTOR_KEYS else "a number"
                _fail(file, spelled, f"{kind} ({unit})", "nothing (the key is missing)")
            continue
        check = _vector3 if key in _VECTOR_KEYS else _number
        values[key] = check(file, spelled, raw[key], unit, sign)
    return values


def _rotors(file: str, doc: Mapping[str, Any]) -> list[tuple[tuple[float, ...], int]]:
    """Validate the [[rotors]] array: at least `MIN_ROTORS` tables of position, direction."""
    raw = doc.get("rotors")
    expected = f"an array of at least {MIN_ROTORS} [[rotors]] tables"
    if raw is None:
        _fail(file, "[[rotors]]", expected, "nothing (the key is missing)")
    if not isinstance(raw, list) or not all(isinstance(r, Mapping) for r in raw):
        found = _describe(raw)
        # A bare number here is most likely a rotor count, not a rotor list.
        if isinstance(raw, int | float) and not isinstance(raw, bool):
            found = f"the number {found}"
        _fail(file, "[[rotors]]", expected, found)
    if len(raw) < MIN_ROTORS:
        _fail(file, "[[rotors]]", expected, f"{len(raw)} rotor{'s' if len(raw) != 1 else ''}")
    rotors = []
    for index, rotor in enumerate(raw, start=1):
        _check_known(file, rotor, "rotors", index)
        for key in _ROTOR_KEYS:
            if key not in rotor:
                what = "an array of 3 numbers (m, body FLU)" if key == "position" else "+1 or -1"
                _fail(file, _spell("rotors", key, index), what, "nothing (the key is missing)")
        position = _vector3(
            file, _spell("rotors", "position", index), rotor["position"], "m, body FLU", None
        )
        direction = rotor["direction"]
        # ±1.0 is harmless, but 0, 2 or true are not a spin direction.
        if isinstance(direction, bool) or direction not in (1, -1):
            _fail(file, _spell("rotors", "direction", index),
                  "+1 (counter-clockwise from above) or -1 (clockwise)", _describe(direction))
        rotors.append((position, int(direction)))
    return rotors


def _unknown_name(file: str, spelled: str, name: str, known: list[str], what: str,
                  spell) -> NoReturn:
    """Reject an unknown effect or effect parameter, suggesting the closest known one."""
    folded = {k.lower(): k for k in known}
    close = ([folded[name.lower()]] if name.lower() in folded
             else difflib.get_close_matches(name, known, n=1, cutoff=0.6))
    hint = f" (did you mean {spell(close[0])}?)" if close else ""
    _fail(file, spelled, f"one of the known {what}s ({', '.join(known)})",
          f"an unknown {what}{hint}")


def _effects(file: str, doc: Mapping[str, Any]) -> list[tuple[str, dict[str, float]]]:
    """Validate the optional ``[effects.NAME]`` tables: known names, keys and numbers."""
    raw = doc.get("effects")
    if raw is None:
        return []
    if not isinstance(raw, Mapping):
        _fail(file, "[effects]", "a table of [effects.NAME] tables", _describe(raw))
    out = []
    for name, table in raw.items():
        if name not in EFFECTS:
            _unknown_name(file, f"[effects.{name}]", name, list(EFFECTS), "effect",
                          lambda n: f"[effects.{n}]")
        if not isinstance(table, Mapping):
            _fail(file, f"[effects.{name}]", "a table of the effect's parameters",
                  _describe(table))
        parameters = {p.name: p for p in EFFECTS[name].parameters}
        values = {}
        for key, value in table.items():
            spelled = f"[effects.{name}].{key}"
            if key not in parameters:
                _unknown_name(file, spelled, key, list(parameters), "key",
                              lambda k, n=name: f"[effects.{n}].{k}")
            values[key] = _number(file, spelled, value, parameters[key].unit,
                                  _EFFECT_SIGNS.get((name, key)))
        out.append((name, values))
    return out


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
        tuple of 3 floats); ``effects``: list of (effect name, {parameter: float}) in
        file order.

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
            _fail(file, key, "a non-empty string", _describe(doc[key]))
    if "mass" not in doc:
        _fail(file, "mass", "a number (kg)", "nothing (the key is missing)")
    mass = _number(file, "mass", doc["mass"], "kg", "positive")
    rotors = _rotors(file, doc)
    tables = {section: _table(file, doc, section) for section in _TABLES}
    return {"name": doc.get("name"), "mass": mass, "rotors": rotors, **tables,
            "effects": _effects(file, doc)}


def _rank_ok(rows: np.ndarray) -> bool:
    """Whether the rows are linearly independent, each row scaled to unit max first."""
    scale = np.max(np.abs(rows), axis=1, keepdims=True)
    if np.any(scale == 0.0):
        return False
    # Rows differ by orders of magnitude (c_T ≈ 1e-5 vs c_M ≈ 1e-7): normalise so
    # the rank test measures geometry, not units.
    s = np.linalg.svd(rows / scale, compute_uv=False)
    return bool(s[-1] > _RANK_RTOL * s[0])


def _check_allocation(file: str, config: VehicleConfig) -> None:
    """Check the 4×k allocation [c_T; c_T y; -c_T x; -ε c_M] has rank 4, naming the gap."""
    from mavsysid.vehicle.allocation import (
        allocation_matrix,  # imports mavsysid.vehicle.config: not at the top
    )

    thrust, roll, pitch, yaw = allocation_matrix(config)
    eps = config.rotor_directions
    directions = "(" + ", ".join(f"{int(e):+d}" for e in eps) + ")"
    if not _rank_ok(np.vstack([thrust, yaw])):
        _fail(file, "[[rotors]].direction",
              "rotors spinning both ways (+1 and -1) so that yaw torque can be produced "
              "independently of thrust", f"all directions {int(eps[0]):+d}")
    if not _rank_ok(np.vstack([thrust, roll, pitch])):
        _fail(file, "[[rotors]].position",
              "rotor positions spanning the x-y plane so that roll and pitch torque can be "
              "produced", "all rotors on one line in the x-y plane")
    if not _rank_ok(np.vstack([thrust, roll, pitch, yaw])):
        _fail(file, "[[rotors]].direction",
              "directions that let yaw torque be produced independently of thrust, roll and "
              "pitch torque", f"directions {directions}, which follow the rotor layout")


def check_vehicle(file: str, config: VehicleConfig) -> None:
    """Check the properties of an assembled configuration that no single key shows.

    Parameters
    ----------
    file : str
        How the file is named in error messages.
    config : VehicleConfig
        The configuration built from a document that passed `validate_document`.

    Raises
    ------
    ConfigError
        Inconsistent inertia, a c_M that is RotorS's ratio c_M/c_T, rotors that cannot
        produce independent thrust, roll, pitch and yaw torque, rotors that cannot lift
        the vehicle, limits in the wrong order, or a motor curve out of range (pwm_min ≥
        pwm_max, thrust_expo > 1).
    """
    params = config.parameters
    j = params.J
    for c in range(3):
        a, b = (c + 1) % 3, (c + 2) % 3
        if j[c] > (1.0 + _INERTIA_TRIANGLE_SLACK) * (j[a] + j[b]):
            names = ("j_x", "j_y", "j_z")
            _fail(file, "[parameters].J",
                  f"principal moments satisfying {names[a]} + {names[b]} ≥ {names[c]} "
                  "(rigid-body triangle inequality)",
                  f"{_describe(list(j))} ({names[a]} + {names[b]} = {j[a] + j[b]:.6g} < "
                  f"{names[c]} = {j[c]:.6g})")
    arm = params.c_M / params.c_T
    if arm >= _MAX_MOMENT_ARM:
        _fail(file, "[parameters].c_M",
              "the absolute moment coefficient in N·m/(rad/s)² (c_M/c_T is a few cm at most)",
              f"{params.c_M!r}, which looks like the ratio c_M/c_T; the absolute coefficient "
              f"is ratio × c_T = {params.c_M!r} × {params.c_T!r} = {params.c_M * params.c_T:.6g}")
    _check_allocation(file, config)
    limits = config.limits
    k = config.rotor_count
    lift = k * params.c_T * limits.rotor_speed_max**2
    weight = config.mass * GRAVITY
    if lift < weight:
        _fail(file, "[limits].rotor_speed_max",
              f"a speed at which the {k} rotors lift the vehicle ({k} × c_T × "
              f"rotor_speed_max² ≥ m g = {weight:.6g} N)",
              f"{limits.rotor_speed_max!r} rad/s giving {lift:.6g} N")
    if limits.rotor_speed_min >= limits.rotor_speed_max:
        _fail(file, "[limits].rotor_speed_min",
              f"a speed in [0, rotor_speed_max = {limits.rotor_speed_max!r}) rad/s",
              repr(limits.rotor_speed_min))
    motor = config.motor
    if motor.pwm_min >= motor.pwm_max:
        _fail(file, "[motor].pwm_min", f"a PWM below pwm_max = {motor.pwm_max!r} µs",
              repr(motor.pwm_min))
    if motor.thrust_expo > 1.0:
        _fail(file, "[motor].thrust_expo", "a number between 0 and 1", repr(motor.thrust_expo))
    if limits.thrust_min_ratio >= limits.thrust_max_ratio:
        _fail(file, "[limits].thrust_min_ratio",
              f"a ratio below thrust_max_ratio = {limits.thrust_max_ratio!r}",
              repr(limits.thrust_min_ratio))
