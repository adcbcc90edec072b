"""Freezing the cyclic collector around timed loops."""

from __future__ import annotations

import gc
import weakref

import pytest
from mavsysid.flight.gc_freeze import frozen_collector


@pytest.mark.parametrize("pause", [False, True])
def test_objects_alive_at_entry_are_frozen_and_released_after(pause):
    """Inside: live objects frozen (collector off with pause); after: unfrozen, collector on."""
    assert gc.isenabled() and gc.get_freeze_count() == 0
    keep = [[] for _ in range(100)]
    with frozen_collector(pause=pause):
        assert gc.get_freeze_count() >= len(keep)
        assert gc.isenabled() is not pause
    assert gc.get_freeze_count() == 0 and gc.isenabled()


class _Node:
    pass


@pytest.mark.parametrize("collect_first", [False, True])
def test_collects_first_and_restores_state_on_error(collect_first):
    """collect_first frees cycles instead of freezing them; an error still restores state."""
    gc.disable()
    try:
        node = _Node()
        node.self = node
        ref = weakref.ref(node)
        del node
        with pytest.raises(RuntimeError), frozen_collector(collect_first=collect_first,
                                                           pause=True):
            assert (ref() is None) is collect_first
            assert not gc.isenabled()
            raise RuntimeError("stop")
        assert gc.get_freeze_count() == 0
        assert not gc.isenabled(), "a collector disabled before stays disabled"
    finally:
        gc.enable()
