"""Keeping Python's cyclic garbage collector out of timed loops.

After the numba kernels are compiled (and a planner graph is built) a process holds so
many objects that a full collection takes 0.1–0.9 s, and it holds the GIL meanwhile: the
simulated vehicle ticks late, a stream overflows its socket buffer, a heartbeat thread
misses beats. Freezing what is alive (`gc.freeze`) moves it out of the collector's view,
so later collections only look at what the loop itself allocates.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["frozen_collector"]


@contextmanager
def frozen_collector(*, collect_first: bool = False, pause: bool = False) -> Iterator[None]:
    """Freeze the objects alive now out of the cyclic collector for the ``with`` body.

    Parameters
    ----------
    collect_first : bool, optional
        Collect the garbage first, so that it is freed rather than frozen.
    pause : bool, optional
        Also disable the collector in the body (reference counting still frees nearly
        everything; the body's reference cycles are collected afterwards).
    """
    if collect_first:
        gc.collect()
    gc.freeze()
    enabled = gc.isenabled()
    if pause:
        gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if enabled:
            gc.enable()
