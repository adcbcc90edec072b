"""Gradient steps for the refinement of the search's best flight (beyond the paper).

The (1+1)-ES of `mavsysid.planner.refine` perturbs one vertex in a random direction; here
the direction is the gradient of the flight's log D-optimality (log det Σ_θ / 6, paper
Eq. dopt) with respect to one interior vertex's block of variables: its flat state
(position to snap, yaw to yaw acceleration) and the log-durations of the two segments
that meet there. Variables are scaled by the ES's perturbation scales
(`mavsysid.planner.refine.POSITION_SCALE` …), which serve as a diagonal preconditioner.

The gradient is taken by forward finite differences through the refiner's cached-prefix
pricing: each probe re-solves the two segments, crosses them by the EKF recursion from
the cached belief before them and the rest of the flight by its cached transfers. A
probe skips the feasibility check (a small move of a feasible flight). An optional
log-barrier on a segment slack (``slack``: segment → its largest normalised limit slack,
negative inside) is added to the objective so that the direction bends away from the
rotor limits before it reaches them.

A step searches along the negative gradient by halving from the vertex's last good
length and keeps a candidate only when it passes every check (`PathRefiner.candidate`:
feasibility, segment time, budget) and lowers the D-optimality. The gradient gains most
early; near a local optimum, pressed against the rotor limits, the ES's random moves gain
more per pricing, so each round goes to whichever has lately gained more per pricing
(counted in pricings, not seconds, so the result depends only on the seed).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from mavsysid.planner.refine import (
    DURATION_SCALE,
    POSITION_SCALE,
    YAW_SCALE,
    PathRefiner,
    RefinablePath,
)
from mavsysid.planner.segments import Segment, VertexState

__all__ = ["BLOCK_SIZE", "GradientRefiner", "block_gradient", "moved_block"]

#: Variables of one vertex block: 15 position derivatives, 3 yaw derivatives, 2 log-durations.
BLOCK_SIZE = 20
#: Forward-difference step in scaled variables.
_FD_STEP = 1e-3
#: Halvings tried along the negative gradient before the step counts as stalled, and
#: doublings tried after a first-length success.
_HALVINGS, _DOUBLINGS = 5, 4
_START_LENGTH = 0.3
_STEP_RANGE = (1e-3, 2.0)
#: ES steps in one round; every _EXPLORE-th round takes the mode not in favour; weight
#: of the last round in a mode's gain rate.
_ES_BURST, _EXPLORE, _RATE_MEMORY = 30, 5, 0.3


def moved_block(path: RefinablePath, i: int, u: np.ndarray, lo: np.ndarray, hi: np.ndarray
                ) -> tuple[list[VertexState], list[float]]:
    """Vertices and durations of ``path`` with vertex ``i``'s block moved by ``u``.

    Parameters
    ----------
    path : RefinablePath
    i : int
        Interior vertex, 1 ≤ i < K (K segments).
    u : ndarray, shape (20,)
        Scaled move: position derivatives (5 × 3, row-major) × `POSITION_SCALE`, yaw
        derivatives × `YAW_SCALE`, then log-durations of segments i − 1 and i ×
        `DURATION_SCALE`.
    lo, hi : ndarray, shape (3,)
        Box the vertex position stays in, m.
    """
    v = path.vertices[i]
    position = v.position + POSITION_SCALE[:, None] * u[:15].reshape(5, 3)
    position[0] = np.clip(position[0], lo, hi)
    vertices = list(path.vertices)
    vertices[i] = VertexState(position, v.yaw + YAW_SCALE * u[15:18])
    durations = [s.duration for s in path.segments]
    durations[i - 1] *= float(np.exp(DURATION_SCALE * u[18]))
    durations[i] *= float(np.exp(DURATION_SCALE * u[19]))
    return vertices, durations


def _objective(refiner: PathRefiner, i: int, u: np.ndarray, check: bool,
               barrier: Callable[[list[Segment]], float] | None) -> tuple[float, object]:
    """(log D-opt + barrier, candidate) of the move ``u`` of vertex ``i``; inf if refused."""
    vertices, durations = moved_block(refiner.path, i, u, refiner.lo, refiner.hi)
    candidate = refiner.candidate(vertices, durations, [i - 1, i], check)
    if candidate is None:
        return np.inf, None
    value = float(np.log(candidate[0].dopt))
    if barrier is not None:
        value += barrier([candidate[0].segments[i - 1], candidate[0].segments[i]])
    return value, candidate


def block_gradient(refiner: PathRefiner, i: int,
                   barrier: Callable[[list[Segment]], float] | None = None,
                   step: float = _FD_STEP) -> tuple[float, np.ndarray]:
    """Forward-difference gradient of log D-opt (+ barrier) in vertex ``i``'s scaled block.

    Returns
    -------
    value : float
        The objective at the current flight.
    gradient : ndarray, shape (20,)
        Per scaled variable (`moved_block`); 0 where a probe was refused (budget or segment
        time at its limit).
    """
    zero = np.zeros(BLOCK_SIZE)
    base, _ = _objective(refiner, i, zero, False, barrier)
    gradient = np.zeros(BLOCK_SIZE)
    for k in range(BLOCK_SIZE):
        zero[k] = step
        value, _ = _objective(refiner, i, zero, False, barrier)
        zero[k] = 0.0
        if np.isfinite(value):
            gradient[k] = (value - base) / step
    return base, gradient


class GradientRefiner:
    """Block-gradient steps on an ES refiner's flight, mixed with ES bursts by recent gain.

    Parameters
    ----------
    es : PathRefiner
        The refiner whose flight, pricing and limits are used (and whose ES steps are the
        fallback).
    slack : callable, optional
        Segment → its largest normalised limit slack (negative inside the limits); with it
        the objective carries μ Σ −log(−slack) over the block's two segments.
    barrier_weight : float, optional
        μ of that barrier.

    Attributes
    ----------
    steps : int
        Pricings spent (each probe, trial and ES step counts one), the budget unit of
        `PlannerSettings.refine_steps`.
    accepted : int
        Changes kept (gradient and ES).
    """

    def __init__(self, es: PathRefiner, slack: Callable[[Segment], float] | None = None,
                 barrier_weight: float = 1e-3) -> None:
        self.es = es
        self.barrier = None if slack is None else _log_barrier(slack, barrier_weight)
        #: Last good step length per vertex (scaled units).
        self._lengths: dict[int, float] = {}
        self.steps = self.accepted = 0
        self.gradient_steps = self.gradient_accepted = 0
        self._next = 1
        self.rounds = 0
        #: Recent log D-opt gain per pricing of gradient steps and of ES bursts; the
        #: gradient goes first.
        self._rates = [1.0, 0.0]

    @property
    def path(self) -> RefinablePath:
        return self.es.path

    def step(self) -> bool:
        """One round: a gradient step on the next interior vertex or a burst of ES steps,
        whichever has lately gained more log D-opt per pricing (the other every
        `_EXPLORE`-th round, to keep its rate current); True when the flight improved."""
        self.rounds += 1
        gradient = len(self.path.segments) >= 2 and (
            self._rates[0] >= self._rates[1]) != (self.rounds % _EXPLORE == 0)
        before, steps = np.log(self.path.dopt), self.steps
        if gradient:
            self.gradient_step(self._next)
            self._next = self._next % (len(self.path.segments) - 1) + 1
        else:
            for _ in range(_ES_BURST):
                self.steps += 1
                self.accepted += self.es.step()
        gain = (before - np.log(self.path.dopt)) / max(self.steps - steps, 1)
        mode = 0 if gradient else 1
        self._rates[mode] += _RATE_MEMORY * (gain - self._rates[mode])
        return bool(gain > 0.0)

    def gradient_step(self, i: int) -> bool:
        """Line search along −∇ of vertex ``i``'s block; True when a change was kept.

        Halves from the vertex's last good length until a candidate is kept; a candidate
        kept at the first length is pushed on by doubling while that still improves (a
        trial costs one pricing, the gradient twenty-one).
        """
        self.gradient_steps += 1
        base, gradient = block_gradient(self.es, i, self.barrier)
        self.steps += BLOCK_SIZE + 1
        norm = float(np.linalg.norm(gradient))
        if not np.isfinite(base) or not 0.0 < norm < np.inf:
            return False
        direction = -gradient / norm
        start = length = self._lengths.get(i, _START_LENGTH)
        best = None
        for _ in range(_HALVINGS):
            best = self._trial(i, length, direction, base)
            if best is not None:
                break
            length *= 0.5
        if best is not None and best[1] == start:
            for _ in range(_DOUBLINGS):
                further = self._trial(i, 2.0 * best[1], direction, best[2])
                if further is None:
                    break
                best = further
        if best is None:
            self._lengths[i] = float(np.clip(length, *_STEP_RANGE))
            return False
        self.es.accept(*best[0])
        self.accepted += 1
        self.gradient_accepted += 1
        self._lengths[i] = float(np.clip(best[1], *_STEP_RANGE))
        return True

    def _trial(self, i: int, length: float, direction: np.ndarray, base: float
               ) -> tuple[tuple, float, float] | None:
        """(candidate, length, objective) of the move ``length`` × ``direction`` when it
        passes every check and lowers both the objective below ``base`` and the D-opt."""
        self.steps += 1
        value, candidate = _objective(self.es, i, length * direction, True, self.barrier)
        if value < base and candidate is not None and candidate[0].dopt < self.path.dopt:
            return candidate, length, value
        return None


def _log_barrier(slack: Callable[[Segment], float], weight: float
                 ) -> Callable[[list[Segment]], float]:
    """μ Σ −log(−slack(segment)): inf at or beyond a limit."""
    def barrier(segments: list[Segment]) -> float:
        total = 0.0
        for segment in segments:
            s = slack(segment)
            if not s < 0.0:
                return np.inf
            total -= np.log(-s)
        return weight * total
    return barrier
