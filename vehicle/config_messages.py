"""The one-line `ConfigError` messages of vehicle configuration checks.

Every problem found in a vehicle TOML file raises `ConfigError` with one line
``"<file>: <key>: <expected>, got <found>"``, keys spelled ``mass``,
``[parameters].c_M``, ``[[rotors]][3].direction``, ``[effects.motor_lag].tau``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NoReturn

from mavsysid.errors import ConfigError

__all__ = ["describe_value", "raise_config_error"]

_MAX_SHOWN = 60


def raise_config_error(file: str, key: str, expected: str, found: str) -> NoReturn:
    """Raise the one-line ConfigError of the module docstring."""
    message = f"{file}: {key}: {expected}, got {found}"
    # One line is part of the CLI contract (exit 2, one-line message).
    raise ConfigError(" ".join(message.split()))


def describe_value(value: Any) -> str:
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
