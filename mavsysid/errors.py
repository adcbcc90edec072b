"""Error types shared by every stage.

Each says what kind of failure it is; the console script (`mavsysid.cli.main`) maps the
kinds to exit codes (docs/architecture.md): an `InputError` is the user's to fix (one line,
no traceback); a `JobFailedError` means the input was fine but the job could not be done.
"""

from __future__ import annotations

__all__ = [
    "ConfigError",
    "InputError",
    "JobFailedError",
    "LogFormatError",
    "MavsysidError",
]


class MavsysidError(Exception):
    """Base class of every error mavsysid reports to a user as one line."""


class InputError(MavsysidError, ValueError):
    """Bad input: a malformed file, an invalid option, an impossible request."""


class ConfigError(InputError):
    """A vehicle configuration file that does not satisfy the schema."""


class LogFormatError(InputError):
    """A flight log that cannot be read: missing columns, bad values, wrong rotor count."""


class JobFailedError(MavsysidError, RuntimeError):
    """The input was valid but the job could not be done."""
