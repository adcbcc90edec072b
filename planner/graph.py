"""The planner's motion graph and belief nodes (paper Algorithm 1's vertices, edges and
beliefs), shared by the search (`mavsysid.planner.rrbt`) and its result."""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
from mavsysid.planner.belief import EdgeTransfer
from mavsysid.planner.segments import Segment, VertexState

__all__ = ["STOP_DURATIONS", "Belief", "Edge", "Vertex", "logdet"]

#: Stopping-segment durations tried for every vertex, shortest feasible wins, s.
STOP_DURATIONS = (1.0, 1.5, 2.0, 3.0, 4.0)


@dataclass(eq=False)
class Edge:
    """A feasible segment src → dst; its transfer is computed when first crossed."""

    src: int
    dst: int
    segment: Segment
    _transfer: EdgeTransfer | None = None


@numba.njit(cache=True)
def _beaten_by(keys: np.ndarray, key: np.ndarray) -> np.ndarray | None:
    """Rows of ``keys`` that ``key`` is no worse than in every column; None when a row
    is no worse than ``key`` in every column (``key`` is dominated)."""
    n, m = keys.shape
    beaten = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        no_worse = True
        no_better = True
        for j in range(m):
            if keys[i, j] > key[j]:
                no_worse = False
            if key[j] > keys[i, j]:
                no_better = False
        if no_worse:
            return None
        beaten[i] = no_better
    return beaten


@dataclass(eq=False)
class Vertex:
    """A graph vertex. ``can_stop`` is False where no stopping segment is feasible: the
    vertex is a pass-through point and no flight may end there."""

    state: VertexState
    stop: Segment | None
    stop_transfer: EdgeTransfer
    can_stop: bool
    out_edges: list[Edge] = field(default_factory=list)
    beliefs: list[Belief] = field(default_factory=list)
    #: One row per kept belief, in the order of ``beliefs``: the keys of the dominance
    #: test (paper Eq. compare), smaller is better in every column.
    keys: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))

    def keep(self, belief: Belief, key: np.ndarray) -> bool:
        """Keep ``belief`` unless a kept one is no worse in every key; prune those it beats.

        Returns False (nothing changes) when ``belief`` is dominated.
        """
        keys = self.keys
        beaten = _beaten_by(keys, key)
        if beaten is None:
            return False
        if beaten.any():
            for i in np.flatnonzero(beaten):
                self.beliefs[i].pruned = True
            self.beliefs[:] = [b for b, lost in zip(self.beliefs, beaten, strict=True)
                               if not lost]
            keys = keys[~beaten]
        self.beliefs.append(belief)
        self.keys = np.vstack((keys, key))
        return True

    @property
    def stop_time(self) -> float:
        """Stop duration here, or the shortest stop still to come (pass-through), s."""
        if not self.can_stop:
            return STOP_DURATIONS[0]
        return 0.0 if self.stop is None else self.stop.duration


@dataclass(eq=False)
class Belief:
    """Σ after a path from the root (paper: a belief node), with its cost in s."""

    sigma: np.ndarray
    cost: float
    vertex: int
    parent: Belief | None
    edge: Edge | None
    logdet: float
    logdet_theta: float
    distinct: int
    is_open: bool
    expanded: int = 0
    pruned: bool = False

    def path_edges(self) -> list[Edge]:
        """The edges from the root to here, in flight order."""
        edges, b = [], self
        while b.edge is not None:
            edges.append(b.edge)
            b = b.parent  # type: ignore[assignment]
        return edges[::-1]


def logdet(m: np.ndarray) -> float:
    """log det m, or +inf when m is not positive definite."""
    sign, value = np.linalg.slogdet(m)
    return float(value) if sign > 0 else np.inf
