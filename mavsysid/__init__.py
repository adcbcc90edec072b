"""mavsysid: plan, fly, estimate and diagnose multirotor system-identification flights.

This package holds the console script and the end-to-end wiring; the domain lives in
`vehicle`, `planner`, `flight` and `estimation`.
"""

from __future__ import annotations

from importlib import metadata

__all__ = ["__version__"]

try:
    __version__ = metadata.version("mavsysid")
except metadata.PackageNotFoundError:  # a bare checkout on sys.path
    __version__ = "0+unknown"
