"""Local refinement of the search's best flight (beyond the paper).

The graph search settles early: its best path reaches most of its final D-optimality in
the first seconds, and later samples rarely improve it. The refinement spends the rest
of the planning time on that path alone, as a (1+1) evolution strategy: perturb one
vertex's flat state (position to snap, yaw to yaw acceleration) or one segment's
duration, re-solve the two fully constrained segments that meet there, and keep the
change only if every segment stays feasible, the flight stays within the budget and the
predicted D-optimality (paper Eq. dopt) drops. The step size follows the 1/5 success
rule. Only the changed segments get new transfers (paper Eq. one_step); the chain is
re-applied from the start, which costs microseconds per segment.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.belief import EdgeTransfer
from planner.segments import Segment, VertexState, connect_fixed

__all__ = ["PathRefiner", "RefinablePath", "StopChoice"]

#: Perturbation scale of each flat derivative at step size 1: position (m) to snap
#: (m/s⁴), then yaw (rad) to yaw acceleration (rad/s²).
_POSITION_SCALE = np.array([0.3, 0.7, 2.0, 5.0, 20.0])
_YAW_SCALE = np.array([0.5, 0.7, 2.0])
#: Log-normal σ of a duration change at step size 1.
_DURATION_SCALE = 0.15
#: 1/5 success rule: a success grows the step by exp(4 a), a failure shrinks it by exp(-a).
_ADAPT = 0.05
_STEP_RANGE = (0.02, 2.0)
#: Vertices stay this far inside the box, m.
_BOX_MARGIN = 0.05


@dataclass(frozen=True)
class StopChoice:
    """The stopping segment at a flight's last vertex (None when it already hovers)."""

    segment: Segment | None
    transfer: EdgeTransfer

    @property
    def duration(self) -> float:
        return 0.0 if self.segment is None else self.segment.duration


@dataclass(frozen=True)
class RefinablePath:
    """A flight as the refinement sees it: K segments between K + 1 vertices, then a stop.

    ``vertices[0]`` is the start hover and never moves.
    """

    vertices: tuple[VertexState, ...]
    segments: tuple[Segment, ...]
    transfers: tuple[EdgeTransfer, ...]
    stop: StopChoice
    dopt: float

    @property
    def duration(self) -> float:
        """Flight time including the stop, s."""
        return sum(s.duration for s in self.segments) + self.stop.duration


class PathRefiner:
    """(1+1)-ES on one flight's vertex states and segment durations.

    Parameters
    ----------
    path : RefinablePath
        The starting flight (the search's best).
    feasible : callable
        Segment → bool, the planner's feasibility check.
    transfer_of : callable
        Segment → EdgeTransfer at the search's propagation rate.
    stop_at : callable
        VertexState → StopChoice, or None when no stop is feasible there.
    dopt_of : callable
        Sequence of transfers (flight order, stop last) → predicted D-optimality.
    box : ndarray, shape (6,)
        Flight volume, m.
    budget : float
        Longest flight, s.
    rng : numpy.random.Generator
    """

    def __init__(self, path: RefinablePath, feasible: Callable[[Segment], bool],
                 transfer_of: Callable[[Segment], EdgeTransfer],
                 stop_at: Callable[[VertexState], StopChoice | None],
                 dopt_of: Callable[[list[EdgeTransfer]], float], box: np.ndarray,
                 budget: float, rng: np.random.Generator) -> None:
        self.path = path
        self.feasible, self.transfer_of, self.stop_at = feasible, transfer_of, stop_at
        self.dopt_of = dopt_of
        self.lo, self.hi = box[:3] + _BOX_MARGIN, box[3:] - _BOX_MARGIN
        self.budget = budget
        self.rng = rng
        self.step_size = 0.3
        self.steps = self.accepted = 0

    def step(self) -> bool:
        """One perturbation; True when it improved the flight."""
        self.steps += 1
        candidate = self._candidate()
        better = candidate is not None and candidate.dopt < self.path.dopt
        if better:
            self.path = candidate  # type: ignore[assignment]
            self.accepted += 1
            self.step_size *= np.exp(4.0 * _ADAPT)
        else:
            self.step_size *= np.exp(-_ADAPT)
        self.step_size = float(np.clip(self.step_size, *_STEP_RANGE))
        return better

    def _candidate(self) -> RefinablePath | None:
        path = self.path
        k = len(path.segments)
        vertices, durations = list(path.vertices), [s.duration for s in path.segments]
        if self.rng.random() < 0.5:
            i = int(self.rng.integers(1, k + 1))
            vertices[i] = self._perturbed_vertex(vertices[i])
            changed = [i - 1, i] if i < k else [i - 1]
        else:
            i = int(self.rng.integers(0, k))
            durations[i] *= float(np.exp(self.rng.normal(0.0, _DURATION_SCALE * self.step_size)))
            changed = [i]
        stop = path.stop
        if vertices[k] is not path.vertices[k]:
            stop = self.stop_at(vertices[k])
            if stop is None:
                return None
        if sum(durations) + stop.duration > self.budget:
            return None
        segments, transfers = list(path.segments), list(path.transfers)
        for j in changed:
            segment = connect_fixed(vertices[j], vertices[j + 1], durations[j])
            if not self.feasible(segment):
                return None
            segments[j] = segment
        for j in changed:
            transfers[j] = self.transfer_of(segments[j])
        dopt = self.dopt_of([*transfers, stop.transfer])
        return RefinablePath(tuple(vertices), tuple(segments), tuple(transfers), stop, dopt)

    def _perturbed_vertex(self, vertex: VertexState) -> VertexState:
        s = self.step_size
        position = vertex.position + s * _POSITION_SCALE[:, None] * self.rng.normal(size=(5, 3))
        position[0] = np.clip(position[0], self.lo, self.hi)
        yaw = vertex.yaw + s * _YAW_SCALE * self.rng.normal(size=3)
        return VertexState(position, yaw)
