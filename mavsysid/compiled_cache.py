"""Where numba caches compiled kernels: one directory per version of mavsysid's sources.

numba keys a cached kernel on its own source file only, so a kernel that inlines a
kernel from another module keeps stale machine code when only the callee changes (and
an upgrade that leaves old cache files behind would do the same). Keying the cache
directory on a hash of all of mavsysid's sources makes any change start afresh. This
must run before numba is first imported, so `mavsysid/__init__.py` calls it;
`NUMBA_CACHE_DIR` set by the user wins.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["configure_numba_cache"]

#: The folders of the checkout that `mavsysid.*` is installed from (pyproject.toml).
_PACKAGES = ("mavsysid", "vehicle", "formats", "planner", "flight", "estimation", "discrepancy",
             "experiments")


def _source_digest() -> str:
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for package in _PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def configure_numba_cache() -> None:
    """Point numba's cache at ``$XDG_CACHE_HOME/mavsysid/numba/<source hash>``."""
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    os.environ["NUMBA_CACHE_DIR"] = str(base / "mavsysid" / "numba" / _source_digest())
