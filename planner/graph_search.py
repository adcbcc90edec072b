"""The search state of one planning run (`mavsysid.planner.rrbt`): the motion graph, the
beliefs at its vertices and the best candidate flight.

Phase 1 (`GraphSearch.grow`) connects a sampled pose from its nearest vertices by a
free-end minimum-snap segment, then to and from every vertex by fully constrained
segments; phase 2 (`GraphSearch.propagate`) pushes open beliefs through the new edges,
pruning with the paper's modular comparison (Eq. compare).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable

import numpy as np
from mavsysid.planner.belief import (
    EdgeTransfer,
    apply_transfer,
    apply_transfer_logdet,
    edge_samples,
    edge_transfer,
    flown_steps,
    identity_transfer,
    riccati_final,
    segments_samples,
    steps_transfer,
)
from mavsysid.planner.feasibility import check_segment, rotor_square_range
from mavsysid.planner.graph import STOP_DURATIONS, Belief, Edge, Vertex, logdet
from mavsysid.planner.kinematic_check import exceeded_limits
from mavsysid.planner.move_time import longest_segment, move_duration_range
from mavsysid.planner.plan_result import PlanProgress
from mavsysid.planner.refine import StopChoice
from mavsysid.planner.search_setup import (
    initial_covariance,
    search_model,
    segment_trajectory,
)
from mavsysid.planner.search_stop import search_stop, search_time_is_up
from mavsysid.planner.segments import (
    Segment,
    VertexState,
    connect_fixed,
    connect_free_end,
    stop_segment,
)
from mavsysid.planner.settings import PlannerSettings
from mavsysid.planner.yaw_branch import nearest_yaw_branch
from mavsysid.vehicle.autopilot_loop import AutopilotLoop
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.linearization import E_THETA, ErrorStateModel
from mavsysid.vehicle.rotation import wrap_angle

__all__ = ["GraphSearch"]

#: Stops end at least this far inside the box, m.
_STOP_MARGIN = 0.2
_PROGRESS_PERIOD = 0.25
#: Vertices (nearest first) from which a sample's free-end connection is tried.
_NEAREST_TRIES = 5
#: Most predicted segment flights kept between their check and their transfer.
_FLOWN_CACHE = 20_000


class GraphSearch:
    """Graph, beliefs and the best candidate of one planning run."""

    def __init__(self, config: VehicleConfig, settings: PlannerSettings, objective: str,
                 progress: Callable[[PlanProgress], None] | None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.config, self.settings, self.objective = config, settings, objective
        self.progress = progress
        self.theta = config.theta
        self.model = ErrorStateModel.for_vehicle(config)
        self.search_model = search_model(config, settings)
        self.rng = np.random.default_rng(settings.seed)
        self.box = np.asarray(settings.box, dtype=float)
        self.vertices: list[Vertex] = []
        self.samples = self.edges_attempted = self.edges = self.propagations = 0
        self.edge_time = self.propagation_time = self.transfer_time = 0.0
        self.refined_steps = self.refined_accepted = 0
        #: Sampled connections refused, by reason (`refusal`); what ended the search
        #: (`mavsysid.planner.search_stop.search_stop`).
        self.refusals: Counter[str] = Counter()
        self.stopped_by = ""
        #: F and Q of the segments last priced by `propagate_segments`, by id.
        self._steps: dict[int, tuple[Segment, np.ndarray, np.ndarray]] = {}
        #: Predicted flights of segments (`samples_of`) with their n² range, by id, when
        #: an autopilot is set.
        self._flown: dict[int, tuple[Segment, tuple[np.ndarray, np.ndarray, float],
                                     tuple[float, float]]] = {}
        self._rotor_range = rotor_square_range(config, settings.rotor_headroom)
        self.best: tuple[float, Belief] | None = None
        self.history: list[tuple[float, float]] = []
        self.first_solution: float | None = None
        self.clock = clock
        self.t0 = clock()
        self.cpu0 = time.thread_time()
        self._last_progress = -np.inf
        self._log_scale = float(np.sum(np.log(self.model.theta_scale)))
        self.sigma0 = initial_covariance(self.model, config, settings)
        self.theta_covariance = settings.theta_covariance
        refines = objective == "dopt" and settings.refine_steps > 0
        self.search_deadline = settings.planning_time * (
            1.0 - settings.refine_share if refines else 1.0)
        self.refine_steps = settings.refine_steps if refines else 0

    # -- budget and termination -----------------------------------------------------------

    def elapsed(self) -> float:
        """Planning time so far, s, on the search's clock (wall time by default)."""
        return self.clock() - self.t0

    def cpu_time(self) -> float:
        """CPU time of this thread since planning began, s."""
        return time.thread_time() - self.cpu0

    def out_of_time(self) -> bool:
        """Past the search phase's share of the planning time (`search_time_is_up`)."""
        return search_time_is_up(self.elapsed(), self.search_deadline,
                                 self.settings.planning_time, self.best_flight_time(),
                                 self.settings.budget)

    def best_flight_time(self) -> float | None:
        """Duration of the best candidate flight, its stop included, s (None: none yet)."""
        if self.best is None:
            return None
        belief = self.best[1]
        return float(belief.cost + self.vertices[belief.vertex].stop_time)

    def done(self) -> bool:
        """Whether the search stops now; what stops it goes to `stopped_by`."""
        s = self.settings
        samples_done = s.max_samples is not None and self.samples >= s.max_samples
        self.stopped_by = search_stop(samples_done, not samples_done and self.out_of_time(),
                                      self.best_flight_time(), s.budget)
        return bool(self.stopped_by)

    # -- geometry -------------------------------------------------------------------------

    def sample_pose(self) -> np.ndarray:
        lo, hi = self.box[:3], self.box[3:]
        return np.array([*self.rng.uniform(lo, hi), self.rng.uniform(-np.pi, np.pi)])

    def longest_segment(self, a: VertexState, b: VertexState) -> float:
        """The longest duration a segment a → b may have, s (`move_time.longest_segment`).

        Parameters
        ----------
        a : VertexState
            Start of the segment: flat state (position and derivatives, m, m/s, …; yaw
            and derivatives, rad, rad/s, …).
        b : VertexState
            End of the segment; only its position (m) and yaw (rad) count.
        """
        return longest_segment(a, b.position[0], float(b.yaw[0]), self.config.limits,
                               self.settings.autopilot_limits)

    def sample_duration(self, a: VertexState, b_position: np.ndarray, b_yaw: float,
                        budget_left: float) -> float | None:
        """A duration for the segment a → (b_position, b_yaw), or None when none fits
        (`move_time.move_duration_range`)."""
        rng = move_duration_range(a, b_position, b_yaw, budget_left, self.config.limits,
                                  self.settings.autopilot_limits)
        return None if rng is None else float(self.rng.uniform(*rng))

    def samples_of(self, segment: Segment) -> tuple[np.ndarray, np.ndarray, float]:
        """States, rotor speeds and step of ``segment`` at the propagation rate: the
        flatness map, or the flight the autopilot is predicted to fly (kept from its check).

        Parameters
        ----------
        segment : Segment
            A polynomial segment (duration s, flat outputs in m and rad).
        """
        autopilot = self.settings.autopilot
        if autopilot is None:
            return edge_samples(segment_trajectory(segment), self.config, self.theta,
                                self.settings.propagation_rate)
        return self._flown_of(segment, autopilot)[1]

    def _flown_of(self, segment: Segment, autopilot: AutopilotLoop
                  ) -> tuple[Segment, tuple[np.ndarray, np.ndarray, float], tuple[float, float]]:
        hit = self._flown.get(id(segment))
        if hit is not None and hit[0] is segment:
            return hit
        flight, dt = flown_steps(segment, self.config, self.theta,
                                 self.settings.propagation_rate, autopilot)
        n2 = flight.rotor_speeds_squared
        entry = (segment, (flight.states(), flight.rotor_speeds, dt),
                 (float(np.min(n2)), float(np.max(n2))))
        if len(self._flown) >= _FLOWN_CACHE:
            self._flown.clear()
        self._flown[id(segment)] = entry
        return entry

    def transfer_of(self, segment: Segment) -> EdgeTransfer:
        states, n, dt = self.samples_of(segment)
        return edge_transfer(self.search_model, states, n, self.theta, dt)

    def propagate_segments(self, sigma: np.ndarray, segments: list[Segment]) -> np.ndarray:
        """Σ after flying ``segments`` in order, by the EKF recursion at the search's rate."""
        self._steps.clear()
        if not segments:
            return sigma
        rate = self.settings.propagation_rate
        if self.settings.autopilot is None:
            samples = segments_samples(segments, self.config, self.theta, rate)
        else:
            samples = [self.samples_of(segment) for segment in segments]
        for segment, (states, n, dt) in zip(segments, samples, strict=True):
            F, Q = self.search_model.discrete(states[:-1], n[:-1], self.theta, dt)
            self._steps[id(segment)] = (segment, F, Q)
            sigma = riccati_final(self.search_model, sigma, F, Q)
        return sigma

    def kept_transfer(self, segment: Segment) -> EdgeTransfer:
        """`transfer_of`, reusing F and Q when ``segment`` was just priced."""
        hit = self._steps.get(id(segment))
        if hit is not None and hit[0] is segment:
            return steps_transfer(self.search_model, hit[1], hit[2])
        return self.transfer_of(segment)

    def refusal(self, segment: Segment) -> str:
        """Why ``segment`` is infeasible ("" when it is feasible): a constraint of
        `check_segment`, or "autopilot QUANTITY" for an autopilot limit.

        Parameters
        ----------
        segment : Segment
            The candidate polynomial segment (duration in s, position coefficients in
            m/s^j, yaw coefficients in rad/s^j), checked against the box, the vehicle's
            constraints and the autopilot's limits of the settings.
        """
        result = check_segment(segment, self.config, self.box,
                               rotor_headroom=self.settings.rotor_headroom,
                               rotor_check=self.settings.rotor_check,
                               theta_covariance=self.theta_covariance,
                               rotor_confidence=self.settings.rotor_confidence)
        if not result.feasible:
            return result.reason
        limits = self.settings.autopilot_limits
        over = "" if limits is None else exceeded_limits(segment, limits)
        if over:
            return f"autopilot {over}"
        return self.flown_refusal(segment)

    def flown_refusal(self, segment: Segment) -> str:
        """"autopilot rotor speed" when the flight the autopilot is predicted to fly needs a
        rotor speed outside the plan's range (`rotor_square_range`), else "".

        Parameters
        ----------
        segment : Segment
            The candidate segment; its predicted flight is kept for its transfer.
        """
        autopilot = self.settings.autopilot
        if autopilot is None or not self.settings.rotor_check:
            return ""
        low, high = self._flown_of(segment, autopilot)[2]
        lo, hi = self._rotor_range
        return "" if lo <= low and high <= hi else "autopilot rotor speed"

    def feasible(self, segment: Segment) -> bool:
        """Whether ``segment`` keeps the vehicle's constraints and the autopilot's limits."""
        return not self.refusal(segment)

    def connects(self, segment: Segment) -> bool:
        """`feasible` for a sampled connection, counting the refusals.

        Parameters
        ----------
        segment : Segment
            The sampled connection; when infeasible, its reason (`refusal`) is counted in
            ``refusals``.
        """
        why = self.refusal(segment)
        if why:
            self.refusals[why] += 1
        return not why

    def stop_at(self, state: VertexState, with_transfer: bool = True) -> StopChoice | None:
        """The shortest feasible stopping segment from ``state``; None if there is none.

        Without ``with_transfer`` a moving state's stop comes without its transfer.
        """
        if np.all(np.abs(state.position[1:]) <= 1e-12) and np.all(np.abs(state.yaw[1:]) <= 1e-12):
            return StopChoice(None, identity_transfer(self.model.dim))
        inner_lo, inner_hi = self.box[:3] + _STOP_MARGIN, self.box[3:] - _STOP_MARGIN
        for duration in STOP_DURATIONS:
            # Where a smooth stop would end, kept inside the box.
            end = np.clip(state.position[0] + 0.5 * duration * state.position[1],
                          inner_lo, inner_hi)
            candidate = stop_segment(state, duration, end)
            if self.feasible(candidate):
                return StopChoice(candidate,
                                  self.transfer_of(candidate) if with_transfer else None)
        return None

    def add_vertex(self, state: VertexState) -> int:
        """A vertex with its stopping segment, when one is feasible."""
        stop = self.stop_at(state)
        if stop is None:
            self.vertices.append(Vertex(state, None, identity_transfer(self.model.dim), False))
        else:
            self.vertices.append(Vertex(state, stop.segment, stop.transfer, True))
        return len(self.vertices) - 1

    def edge_transfer(self, edge: Edge) -> EdgeTransfer:
        """The edge's transfer, computed the first time a belief crosses it (many never are)."""
        if edge._transfer is None:
            start = self.clock()
            edge._transfer = self.transfer_of(edge.segment)
            self.transfer_time += self.clock() - start
        return edge._transfer

    def add_edge(self, src: int, dst: int, segment: Segment) -> Edge:
        edge = Edge(src, dst, segment)
        self.vertices[src].out_edges.append(edge)
        self.edges += 1
        return edge

    def try_fixed(self, src: int, dst: int, budget_left: float) -> Edge | None:
        a, b = self.vertices[src].state, nearest_yaw_branch(
            self.vertices[dst].state, float(self.vertices[src].state.yaw[0]))
        duration = self.sample_duration(a, b.position[0], float(b.yaw[0]), budget_left)
        if duration is None:
            return None
        self.edges_attempted += 1
        segment = connect_fixed(a, b, duration)
        return self.add_edge(src, dst, segment) if self.connects(segment) else None

    # -- beliefs --------------------------------------------------------------------------

    def belief(self, sigma: np.ndarray, cost: float, vertex: int, parent: Belief | None,
               edge: Edge | None, logdets: tuple[float, float] | None = None) -> Belief:
        stop_time = self.vertices[vertex].stop_time
        distinct = 0
        if parent is not None and self.objective == "random":
            distinct = parent.distinct + all(e is not edge for e in parent.path_edges())
        if logdets is None:
            logdets = (logdet(sigma), logdet(sigma[E_THETA, E_THETA]))
        return Belief(sigma, cost, vertex, parent, edge, logdets[0], logdets[1], distinct,
                       is_open=cost + stop_time < self.settings.budget)

    def append(self, belief: Belief) -> bool:
        """Keep a belief unless another at its vertex dominates it (paper Eq. compare)."""
        if not self.vertices[belief.vertex].keep(belief, self._dominance_key(belief)):
            return False
        self.consider(belief)
        return True

    def _dominance_key(self, b: Belief) -> np.ndarray:
        """Keys of paper Eq. compare, each smaller-is-better: a belief dominates another
        when it is no worse in all of them."""
        if self.objective == "random":  # no information in the baseline's choices
            return np.array([b.cost, -b.distinct, 0.0])
        return np.array([b.cost, b.logdet, b.logdet_theta])

    def consider(self, belief: Belief) -> None:
        """Track the best candidate flight: the belief with its stop, inside the budget."""
        vertex = self.vertices[belief.vertex]
        if (belief.edge is None or not vertex.can_stop
                or belief.cost + vertex.stop_time > self.settings.budget):
            return
        final = apply_transfer(belief.sigma, vertex.stop_transfer)
        dopt = self.dopt(final)
        key = -belief.distinct if self.objective == "random" else dopt
        if self.best is None or key < self.best[0]:
            self.best = (key, belief)
            self.history.append((self.elapsed(), dopt))
            if self.first_solution is None:
                self.first_solution = self.elapsed()

    def dopt(self, sigma: np.ndarray) -> float:
        """det(Σ_θ)^(1/6) in SI units (paper Eq. dopt), computed in log space."""
        return float(np.exp((logdet(sigma[E_THETA, E_THETA]) + 2.0 * self._log_scale) / 6.0))

    def propagate(self, queue: list[Belief]) -> None:
        """Phase 2: push open beliefs through the edges they have not crossed yet."""
        start = self.clock()
        transfers0 = self.transfer_time
        budget = self.settings.budget
        while queue and not self.out_of_time():
            b = queue.pop()
            if b.pruned or not b.is_open:
                continue
            edges = self.vertices[b.vertex].out_edges
            for edge in edges[b.expanded:]:
                dst = self.vertices[edge.dst]
                cost = b.cost + edge.segment.duration
                if cost + dst.stop_time > budget:
                    continue
                self.propagations += 1
                sigma, full, theta = apply_transfer_logdet(b.sigma, self.edge_transfer(edge))
                new = self.belief(sigma, cost, edge.dst, b, edge, (full, theta))
                if self.append(new):
                    queue.append(new)
            b.expanded = len(edges)
            self.report()
        self.propagation_time += self.clock() - start - (self.transfer_time - transfers0)

    def report(self, force: bool = False) -> None:
        now = self.elapsed()
        if self.progress is None or (not force and now - self._last_progress < _PROGRESS_PERIOD):
            return
        self._last_progress = now
        beliefs = sum(len(v.beliefs) for v in self.vertices)
        best = None if self.best is None else self.history[-1][1]
        self.progress(PlanProgress(now, self.samples, len(self.vertices), self.edges, beliefs,
                                   best))

    # -- phase 1 --------------------------------------------------------------------------

    def grow(self) -> list[Belief]:
        """One sample: a new vertex connected to the graph; returns beliefs to propagate.

        The free-end connection is tried from the nearest vertices with open beliefs, up
        to `_NEAREST_TRIES` of them: a graph vertex is usually moving, and its nearest
        position is often not the one that can turn towards the sample.
        """
        self.samples += 1
        pose = self.sample_pose()
        start = self.clock()
        positions = np.array([v.state.position[0] for v in self.vertices])
        order = np.argsort(np.linalg.norm(positions - pose[:3], axis=1))
        queue: list[Belief] = []
        tries = 0
        for nearest in order:
            nearest = int(nearest)
            open_costs = [b.cost for b in self.vertices[nearest].beliefs if b.is_open]
            if not open_costs:
                continue
            tries += 1
            near_state = self.vertices[nearest].state
            yaw0 = float(near_state.yaw[0])
            yaw = yaw0 + wrap_angle(float(pose[3]) - yaw0)
            duration = self.sample_duration(near_state, pose[:3], yaw,
                                            self.settings.budget - min(open_costs))
            if duration is not None:
                self.edges_attempted += 1
                segment = connect_free_end(near_state, pose[:3], yaw, duration)
                if self.connects(segment):
                    queue = self._connect_all(nearest, self.add_vertex(segment.end_state()),
                                              segment)
                    break
            if tries == _NEAREST_TRIES:
                break
        self.edge_time += self.clock() - start
        return queue

    def _connect_all(self, nearest: int, new: int, segment: Segment) -> list[Belief]:
        """Edges nearest → new (free end), new → nearest, and to and from every vertex."""
        self.add_edge(nearest, new, segment)
        queue = [b for b in self.vertices[nearest].beliefs if b.is_open]
        budget = self.settings.budget
        self.try_fixed(new, nearest, budget)
        for u in range(len(self.vertices) - 1):
            if u == nearest:
                continue
            if self.try_fixed(u, new, budget) is not None:
                queue.extend(b for b in self.vertices[u].beliefs if b.is_open)
            self.try_fixed(new, u, budget)
        return queue

    def run(self) -> None:
        pose = self.settings.start_pose
        root_vertex = self.add_vertex(VertexState.hover(pose[:3], float(pose[3])))
        assert root_vertex == 0
        root = self.belief(self.sigma0, 0.0, 0, None, None)
        self.vertices[0].keep(root, self._dominance_key(root))
        while not self.done():
            self.propagate(self.grow())
            self.report()
        self.report(force=True)

    # -- pricing a flight -----------------------------------------------------------------

    def flight_dopt(self, transfers: list[EdgeTransfer]) -> float:
        """Predicted D-optimality after a chain of transfers from the initial belief."""
        sigma = self.sigma0
        for transfer in transfers:
            sigma = apply_transfer(sigma, transfer)
        return self.dopt(sigma)
