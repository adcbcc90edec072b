"""The planner's motion graph and belief nodes (paper Algorithm 1's vertices, edges and
beliefs), shared by the search (`planner.rrbt`) and its result."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planner.belief import EdgeTransfer
from planner.segments import Segment, VertexState

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
