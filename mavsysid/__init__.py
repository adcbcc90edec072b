"""mavsysid: plan, fly, estimate and diagnose multirotor system-identification flights.

One installed import name for the whole toolchain; its subpackages live in the checkout's
top-level folders (docs/architecture.md): `mavsysid.vehicle` (the model), `mavsysid.formats`
(the files the stages exchange), `mavsysid.planner`, `mavsysid.flight`, `mavsysid.estimation`,
`mavsysid.discrepancy`, `mavsysid.experiments` and the command line, `mavsysid.cli`.
"""

from __future__ import annotations

from importlib import metadata

from mavsysid.compiled_cache import configure_numba_cache

configure_numba_cache()  # before any submodule imports numba

__all__ = ["__version__"]

try:
    __version__ = metadata.version("mavsysid")
except metadata.PackageNotFoundError:  # a bare checkout on sys.path
    __version__ = "0+unknown"
