"""Local refinement of the search's best flight (beyond the paper).

The graph search settles early: its best path reaches most of its final D-optimality in
the first seconds, and later samples rarely improve it. The refinement spends the rest
of the planning time on that path alone, as a (1+1) evolution strategy: perturb one
vertex's flat state (position to snap, yaw to yaw acceleration) or one segment's
duration, re-solve the two fully constrained segments that meet there, and keep the
change only if every segment stays feasible, the flight stays within the budget and the
predicted D-optimality (paper Eq. dopt) drops. The step size follows the 1/5 success
rule.

Pricing a candidate: the belief before the first changed segment is cached, the changed
segments are crossed by the plain EKF covariance recursion (several times cheaper than
building their one-step transfers, paper Eq. one_step), and the unchanged rest of the
flight by its cached transfers. Transfers are built only for the changes that are kept
(about one in ten).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from mavsysid.planner.belief import EdgeTransfer
from mavsysid.planner.segments import Segment, VertexState, connect_fixed

__all__ = ["DURATION_SCALE", "POSITION_SCALE", "YAW_SCALE", "FlightPricing", "PathRefiner",
           "RefinablePath", "StopChoice", "split_path"]

#: Perturbation scale of each flat derivative at step size 1: position (m) to snap
#: (m/s⁴), then yaw (rad) to yaw acceleration (rad/s²).
POSITION_SCALE = np.array([0.3, 0.7, 2.0, 5.0, 20.0])
YAW_SCALE = np.array([0.5, 0.7, 2.0])
#: Log-normal σ of a duration change at step size 1.
DURATION_SCALE = 0.15
#: 1/5 success rule: a success grows the step by exp(4 a), a failure shrinks it by exp(-a).
_ADAPT = 0.05
_STEP_RANGE = (0.02, 2.0)
#: Vertices stay this far inside the box, m.
_BOX_MARGIN = 0.05


@dataclass(frozen=True)
class StopChoice:
    """The stopping segment at a flight's last vertex (None when it already hovers).

    ``transfer`` may be None for a stop that has not been kept yet: the refiner builds it
    only when a change that needs it is accepted.
    """

    segment: Segment | None
    transfer: EdgeTransfer | None

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


@dataclass(frozen=True)
class FlightPricing:
    """How the refiner turns segments into a predicted D-optimality.

    Attributes
    ----------
    sigma0 : ndarray, shape (18, 18)
        Belief at the start hover.
    propagate : callable
        (Σ, segments) → Σ after flying the segments in order (EKF recursion).
    transfer : callable
        Segment → its one-step transfer (`mavsysid.planner.belief.edge_transfer`).
    apply : callable
        (Σ, transfer) → Σ after the transfer.
    dopt : callable
        Σ → predicted D-optimality det(Σ_θ)^(1/6), SI.
    identity : object
        The transfer of an empty stop (already hovering).
    """

    sigma0: np.ndarray
    propagate: Callable[[np.ndarray, Sequence[Segment]], np.ndarray]
    transfer: Callable[[Segment], EdgeTransfer]
    apply: Callable[[np.ndarray, EdgeTransfer], np.ndarray]
    dopt: Callable[[np.ndarray], float]
    identity: EdgeTransfer


def split_path(path: RefinablePath, pieces: int, feasible: Callable[[Segment], bool],
               transfer_of: Callable[[Segment], EdgeTransfer]) -> RefinablePath:
    """The same flight with every segment cut into ``pieces`` equal parts.

    A degree-9 Hermite segment between two of its own interior states is the original
    polynomial, so the flight and its D-optimality stay the same (to rounding); the new
    vertices give the refinement shorter segments, hence faster manoeuvres, to work
    with. A segment whose pieces fail the feasibility check (rounding at a limit) stays
    whole.
    """
    if pieces < 1:
        raise ValueError(f"pieces must be ≥ 1, got {pieces}")
    vertices, segments, transfers = [path.vertices[0]], [], []
    for segment, end, transfer in zip(path.segments, path.vertices[1:], path.transfers,
                                      strict=True):
        cut, inner = [], vertices[-1]
        for k in range(1, pieces + 1):
            vertex = end if k == pieces else segment.state_at(k / pieces)
            cut.append((vertex, connect_fixed(inner, vertex, segment.duration / pieces)))
            inner = vertex
        if pieces > 1 and all(feasible(piece) for _, piece in cut):
            vertices.extend(v for v, _ in cut)
            segments.extend(piece for _, piece in cut)
            transfers.extend(transfer_of(piece) for _, piece in cut)
        else:
            vertices.append(end)
            segments.append(segment)
            transfers.append(transfer)
    return RefinablePath(tuple(vertices), tuple(segments), tuple(transfers), path.stop,
                         path.dopt)


class PathRefiner:
    """(1+1)-ES on one flight's vertex states and segment durations.

    Parameters
    ----------
    path : RefinablePath
        The starting flight (the search's best); its transfers and stop transfer are set.
    feasible : callable
        Segment → bool, the planner's feasibility check.
    stop_at : callable
        VertexState → StopChoice (transfer may be None), or None when no stop is feasible.
    pricing : FlightPricing
        Belief propagation of the planner's search model.
    box : ndarray, shape (6,)
        Flight volume, m.
    budget : float
        Longest flight, s.
    rng : numpy.random.Generator
    segment_time_max : float or callable, optional
        Longest segment, s (the planner limit `Limits.segment_time_max`), or (start, end
        vertex) → the longest segment between them
        (`mavsysid.planner.graph_search.GraphSearch.longest_segment`).
    shortest_flight : float, optional
        Flight time, stop included, below which no change is kept, s (at most the
        starting flight's): the budget is the flight asked for, and sharper but shorter
        manoeuvres would otherwise trade it away.
    """

    def __init__(self, path: RefinablePath, feasible: Callable[[Segment], bool],
                 stop_at: Callable[[VertexState], StopChoice | None], pricing: FlightPricing,
                 box: np.ndarray, budget: float, rng: np.random.Generator,
                 segment_time_max: float | Callable[[VertexState, VertexState], float] = np.inf,
                 shortest_flight: float = 0.0) -> None:
        self.path = path
        self.feasible, self.stop_at, self.pricing = feasible, stop_at, pricing
        self.lo, self.hi = box[:3] + _BOX_MARGIN, box[3:] - _BOX_MARGIN
        self.budget = budget
        self.shortest_flight = min(shortest_flight, path.duration)
        self.longest: Callable[[VertexState, VertexState], float] = (
            segment_time_max if callable(segment_time_max)
            else lambda _a, _b, t=float(segment_time_max): t)
        self.rng = rng
        self.step_size = 0.3
        self.steps = self.accepted = 0
        self._prefix = [pricing.sigma0]
        self._extend_prefix()

    def _extend_prefix(self) -> None:
        """Beliefs before each segment (and before the stop) from the cached transfers."""
        sigma = self._prefix[-1]
        for transfer in self.path.transfers[len(self._prefix) - 1:]:
            sigma = self.pricing.apply(sigma, transfer)
            self._prefix.append(sigma)

    def step(self) -> bool:
        """One perturbation; True when it improved the flight."""
        self.steps += 1
        candidate = self._candidate()
        better = candidate is not None and candidate[0].dopt < self.path.dopt
        if better:
            self.accept(*candidate)  # type: ignore[misc]
            self.accepted += 1
            self.step_size *= np.exp(4.0 * _ADAPT)
        else:
            self.step_size *= np.exp(-_ADAPT)
        self.step_size = float(np.clip(self.step_size, *_STEP_RANGE))
        return better

    def accept(self, path: RefinablePath, changed: list[int]) -> None:
        """Keep ``path``: build the transfers of its changed segments and stop."""
        transfers = list(path.transfers)
        for j in changed:
            transfers[j] = self.pricing.transfer(path.segments[j])
        stop = path.stop
        if stop.transfer is None:
            transfer = (self.pricing.identity if stop.segment is None
                        else self.pricing.transfer(stop.segment))
            stop = StopChoice(stop.segment, transfer)
        self.path = RefinablePath(path.vertices, path.segments, tuple(transfers), stop, path.dopt)
        del self._prefix[changed[0] + 1:]
        self._extend_prefix()

    def _candidate(self) -> tuple[RefinablePath, list[int]] | None:
        path = self.path
        k = len(path.segments)
        vertices, durations = list(path.vertices), [s.duration for s in path.segments]
        if self.rng.random() < 0.5:
            i = int(self.rng.integers(1, k + 1))
            vertices[i] = self._perturbed_vertex(vertices[i])
            changed = [i - 1, i] if i < k else [i - 1]
        else:
            i = int(self.rng.integers(0, k))
            durations[i] *= float(np.exp(self.rng.normal(0.0, DURATION_SCALE * self.step_size)))
            changed = [i]
        return self.candidate(vertices, durations, changed)

    def candidate(self, vertices: list[VertexState], durations: list[float],
                  changed: list[int], check: bool = True
                  ) -> tuple[RefinablePath, list[int]] | None:
        """The flight with new ``vertices`` and ``durations``, priced, or None when out of
        the limits.

        Only the segments ``changed`` (contiguous indices) are re-solved, and the stop
        only when the last vertex moved. None when a changed segment is longer than its
        longest (``segment_time_max``), the flight longer than the budget or shorter than
        ``shortest_flight``, a changed segment or the stop infeasible (``check`` False skips
        the feasibility checks: for finite-difference probes of a kept flight).
        """
        path, k = self.path, len(self.path.segments)
        if any(durations[j] > self.longest(vertices[j], vertices[j + 1]) for j in changed):
            return None
        stop = path.stop
        if vertices[k] is not path.vertices[k]:
            stop = self.stop_at(vertices[k])
            if stop is None:
                return None
        if not self.shortest_flight <= sum(durations) + stop.duration <= self.budget:
            return None
        segments = list(path.segments)
        for j in changed:
            segment = connect_fixed(vertices[j], vertices[j + 1], durations[j])
            if check and not self.feasible(segment):
                return None
            segments[j] = segment
        dopt = self.price(segments, changed, stop)
        return RefinablePath(tuple(vertices), tuple(segments), path.transfers, stop, dopt), changed

    def price(self, segments: list[Segment], changed: list[int], stop: StopChoice) -> float:
        """D-opt of the flight with ``changed`` segments (contiguous) and ``stop`` replaced."""
        p = self.pricing
        fly = [segments[j] for j in changed]
        new_stop = stop is not self.path.stop
        if new_stop and stop.segment is not None:
            fly.append(stop.segment)
        sigma = p.propagate(self._prefix[changed[0]], fly)
        for transfer in self.path.transfers[changed[-1] + 1:]:
            sigma = p.apply(sigma, transfer)
        if not new_stop:
            sigma = p.apply(sigma, self.path.stop.transfer)
        return p.dopt(sigma)

    def _perturbed_vertex(self, vertex: VertexState) -> VertexState:
        s = self.step_size
        position = vertex.position + s * POSITION_SCALE[:, None] * self.rng.normal(size=(5, 3))
        position[0] = np.clip(position[0], self.lo, self.hi)
        yaw = vertex.yaw + s * YAW_SCALE * self.rng.normal(size=3)
        return VertexState(position, yaw)
