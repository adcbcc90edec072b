"""Feasibility of a polynomial segment: paper Eq. (constraints) plus speed and rotor limits.

Checked in this order (`mavsysid.vehicle.config.Limits`): position in the flight box; collective
thrust m‖a − g‖ in [thrust_min_ratio, thrust_max_ratio] · m g (the ratio bounds of
`mavsysid.vehicle.thrust_envelope`); ‖v‖ ≤ speed_max (a
planner limit in docs/architecture.md); |ψ̈| ≤ yaw_acceleration_max; ‖ω‖ ≤ body_rate_max; rotor
speeds in [rotor_speed_min, rotor_speed_max]² — the Firefly has so little yaw authority
that without these the planner would plan yaw it cannot fly. The vehicle's
``[limits] allocation`` says how: n² = A⁺ w in the box ("pseudo_inverse", the default), or
the wrench inside the exact allocation polytope ("exact"), both as slabs of
`mavsysid.vehicle.allocation_polytope`.

The first four are polynomials in s = τ/T, decided exactly (to rounding) by Bernstein
subdivision (`mavsysid.planner.bernstein`). ω and n² are sampled on a grid (10 ms by
default); Mueller-style, each interval where a sample comes within a conservative local
bound of a limit (safety × |f'| × half the step) is split ten-fold, down to 0.1 ms, and
rejected if still undecided there. The pointwise flatness is
`mavsysid.vehicle.flatness.flat_sample`,
the numba kernel `flat_to_state` runs too.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import ceil

import numba
import numpy as np
from mavsysid.planner.bernstein import (
    bernstein_matrix,
    linear_violation,
    range_violation,
    square_norm,
    square_weights,
)
from mavsysid.planner.sample_slacks import sample_slacks
from mavsysid.planner.segments import Segment, VertexState
from mavsysid.vehicle.allocation import allocation_pinv
from mavsysid.vehicle.allocation_polytope import allocation_slabs
from mavsysid.vehicle.config import GRAVITY, VehicleConfig
from mavsysid.vehicle.flatness import SAMPLE_SIZE
from mavsysid.vehicle.thrust_envelope import thrust_envelope

from mavsysid.errors import InputError

__all__ = ["CONSTRAINTS", "UNBOUNDED_SQUARE", "FeasibilityResult", "check_rotor_headroom",
           "check_segment", "check_vertex_state", "rotor_square_range", "segment_slack"]

#: Constraint names in the order they are checked (``FeasibilityResult.reason``).
CONSTRAINTS = ("box", "thrust", "speed", "yaw_acceleration", "body_rate", "rotor_speed")
_BOX, _THRUST, _SPEED, _YAW_ACC, _RATE, _ROTOR = range(len(CONSTRAINTS))

_REFINE = 10  # sub-intervals per refined grid interval
_MIN_STEP = 1e-4  # s; a grid interval still undecided at this step is rejected
_SLACK = 1e-9  # sampled slacks this close to a limit are refined (and rejected at 0.1 ms)


@dataclass(frozen=True)
class FeasibilityResult:
    """Outcome of a feasibility check.

    Attributes
    ----------
    feasible : bool
        True when every constraint holds on the whole segment.
    reason : str
        The first constraint found violated (one of `CONSTRAINTS`), "" when feasible.
    time : float or None
        Local time of the violation (or of the undecided interval), s; None if feasible.
    samples : int
        Pointwise flatness evaluations spent (a cost measure).
    """

    feasible: bool
    reason: str = ""
    time: float | None = None
    samples: int = 0

    def __bool__(self) -> bool:
        return self.feasible


_BERN_POS, _BERN_VEL, _BERN_ACC, _BERN_YAW = (bernstein_matrix(n) for n in (9, 8, 7, 3))
_SQUARE_VEL, _SQUARE_ACC = square_weights(8), square_weights(7)


@numba.njit(cache=True)
def _polynomial_scan(dc: np.ndarray, box: np.ndarray, lim: np.ndarray) -> tuple[int, float]:
    """Exact checks of the polynomial constraints: (constraint index, s) or (-1, 0).

    ``dc`` is `Segment.derivative_coeffs`: column 3k + axis the k-th τ-derivative of
    position in powers of s, column 15 + k of yaw. Each limit is tightened by the
    rounding error the monomial coefficients may carry (`mavsysid.planner.bernstein`:
    a small multiple of ε × Σ|terms|), so that no sampler, this one or another, sees a
    violation where this accepts.
    """
    for axis in range(3):
        s = linear_violation(_BERN_POS, dc[:, axis].copy(), box[axis], box[axis + 3])
        if s >= 0.0:
            return _BOX, s
    # Paper Eq. (constraints): thrust per mass ‖a + [0, 0, g]‖, compared squared.
    f, tol = square_norm(dc, 6, _BERN_ACC, _SQUARE_ACC, GRAVITY)
    s = range_violation(f, lim[1] + tol, lim[2] - tol)
    if s >= 0.0:
        return _THRUST, s
    f, tol = square_norm(dc, 3, _BERN_VEL, _SQUARE_VEL, 0.0)
    s = range_violation(f, -np.inf, lim[3] - tol)
    if s >= 0.0:
        return _SPEED, s
    # Paper Eq. (constraints): |ψ̈| ≤ ψ̈_max, a cubic.
    s = linear_violation(_BERN_YAW, dc[:4, 17].copy(), -lim[4], lim[4])
    if s >= 0.0:
        return _YAW_ACC, s
    return -1, 0.0


@numba.njit(cache=True)
def _undecided(g: np.ndarray, i: int, safety: float) -> int:
    """Column whose bound on [t_i, t_i+1] reaches its limit, or -1.

    Bound: larger sample + safety × |f'| × step / 2, with |f'| × step the largest
    neighbouring difference.
    """
    n = g.shape[0] - 1
    for f in range(g.shape[1]):
        d = abs(g[i + 1, f] - g[i, f])
        if i > 0:
            d = max(d, abs(g[i, f] - g[i - 1, f]))
        if i + 2 <= n:
            d = max(d, abs(g[i + 2, f] - g[i + 1, f]))
        if max(g[i, f], g[i + 1, f]) + 0.5 * safety * d > -_SLACK:
            return f
    return -1


@numba.njit(cache=True)
def _adaptive_scan(dc: np.ndarray, duration: float, intervals: int, safety: float,
                   kernel: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
                   ) -> tuple[int, float, int]:
    """Grid check of ω and n², refining undecided intervals: (column, time, evaluations).

    Column -1 when feasible, else the slack (0 body rate, 1+ a rotor slab) that a sample
    violates or that stayed undecided down to the minimum step, at local ``time``.
    """
    lim, J, normals, bounds, spread = kernel
    v = np.empty(12 + SAMPLE_SIZE)
    # Level 0 is the whole segment in ``intervals`` parts; deeper levels split each
    # undecided interval of the level above into _REFINE parts.
    starts, columns = np.zeros(1), np.zeros(1, dtype=np.int64)
    count, width, parts, evaluations = 1, duration, intervals, 0
    while count > 0:
        if width <= _MIN_STEP * (1.0 + 1e-9):
            return columns[0], starts[0], evaluations
        step = width / parts
        g = np.empty((parts + 1, 1 + normals.shape[0]))
        next_starts = np.empty(count * parts)
        next_columns = np.empty(count * parts, dtype=np.int64)
        next_count = 0
        for q in range(count):
            for i in range(parts + 1):
                t = min(starts[q] + i * step, duration)
                sample_slacks(dc, t / duration, lim, J, normals, bounds, spread, v, g, i)
                for f in range(g.shape[1]):
                    if g[i, f] > 0.0:
                        return f, t, evaluations + i + 1
            evaluations += parts + 1
            for i in range(parts):
                f = _undecided(g, i, safety)
                if f >= 0:
                    next_starts[next_count], next_columns[next_count] = starts[q] + i * step, f
                    next_count += 1
        starts, columns, count = next_starts, next_columns, next_count
        width, parts = step, _REFINE
    return -1, 0.0, evaluations


@numba.njit(cache=True)
def _largest_slack(dc: np.ndarray, duration: float, intervals: int,
                   kernel: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
                   ) -> float:
    """The largest sampled slack (body rate and rotor slabs) on a uniform grid."""
    lim, J, normals, bounds, spread = kernel
    v = np.empty(12 + SAMPLE_SIZE)
    g = np.empty((1, 1 + normals.shape[0]))
    worst = -np.inf
    for i in range(intervals + 1):
        sample_slacks(dc, i / intervals, lim, J, normals, bounds, spread, v, g, 0)
        for f in range(g.shape[1]):
            worst = max(worst, g[0, f])
    return worst


@numba.njit(cache=True)
def _check_kernel(dc: np.ndarray, duration: float, box: np.ndarray,
                  kernel: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                  intervals: int,
                  safety: float) -> tuple[int, float, int]:
    """All checks, cheap exact ones first: (constraint index or -1, time, evaluations)."""
    which, s = _polynomial_scan(dc, box, kernel[0])
    if which >= 0:
        return which, s * duration, 0
    column, time, evaluations = _adaptive_scan(dc, duration, intervals, safety, kernel)
    if column < 0:
        return -1, 0.0, evaluations
    return (_RATE if column == 0 else _ROTOR), time, evaluations


# (config, theta) → kernel inputs; keyed by identity (a config's value hash costs more
# than a check), holding the config so that its id cannot be reused while cached.
_KERNEL_CACHE: dict[tuple[int, bytes, float, bool], tuple[VehicleConfig, tuple]] = {}
#: n² bound, (rad/s)², of a check without rotor limits: beyond any flatness result.
UNBOUNDED_SQUARE = 1e300


def rotor_square_range(config: VehicleConfig, headroom: float = 0.0) -> tuple[float, float]:
    """The n² range a plan may use, (rad/s)²: the rotor range less ``headroom`` at each end.

    ``headroom`` is a fraction of n²_max − n²_min kept free at both ends for the
    autopilot's feedback, and for the true vehicle, whose θ is not the planner's: with a
    prior 30 % off, a flight planned to the last rotor rad/s saturates and can diverge.
    """
    lim = config.limits
    lo, hi = lim.rotor_speed_min**2, lim.rotor_speed_max**2
    return lo + headroom * (hi - lo), hi - headroom * (hi - lo)


def check_rotor_headroom(config: VehicleConfig, headroom: float,
                         name: str = "rotor headroom") -> None:
    """Refuse a headroom outside [0, 0.5) or one whose range excludes the hover speeds.

    Raises
    ------
    InputError
        One line naming ``name`` (the option that set it) and the problem.
    """
    if not 0.0 <= headroom < 0.5:
        raise InputError(f"{name} {headroom:g}: expected a fraction in [0, 0.5)")
    lo, hi = rotor_square_range(config, headroom)
    hover = allocation_pinv(config, config.theta) @ np.array([config.hover_thrust, 0, 0, 0])
    if hover.min() < lo or hover.max() > hi:
        raise InputError(
            f"{name} {headroom:g}: leaves rotor speeds {np.sqrt(lo):.0f}–{np.sqrt(hi):.0f} "
            f"rad/s, without the hover speed {np.sqrt(hover.max()):.0f} rad/s")


#: Indices in θ of (c_T, c_M, j_x, j_y, j_z), the parameters the wrench check depends on.
_WRENCH_THETA = np.array([0, 2, 3, 4, 5])


def _kernel_inputs(config: VehicleConfig, theta: np.ndarray | None, headroom: float = 0.0,
                   rotor_check: bool = True, theta_covariance: np.ndarray | None = None,
                   rotor_confidence: float = 0.0) -> tuple[np.ndarray, ...]:
    """(limits, J, slab normals, slab bounds, spread) for the kernels, cached per config,
    θ, rotor headroom, check and spread.

    The slabs are ``config.allocation``'s (`allocation_slabs`): A⁺ rows per rotor, or the
    exact allocation polytope's facet directions; bounds = [lower, upper, scale], (3, m).
    spread = z² Σ of relative (c_T, c_M, j_x, j_y, j_z), (5, 5); zero without a covariance.

    limits = [m, (r_min g)², (r_max g)², v_max², ψ̈_max, ω_max, n²_min, n²_max]; without
    ``rotor_check`` the n² range is unbounded (±`UNBOUNDED_SQUARE`), every slack ≈ −1.
    """
    th = config.theta if theta is None else np.asarray(theta, dtype=float).reshape(6)
    spread = np.zeros((5, 5))
    if theta_covariance is not None and rotor_check and rotor_confidence > 0.0:
        cov = np.asarray(theta_covariance, dtype=float).reshape(6, 6)
        spread = rotor_confidence**2 * cov[np.ix_(_WRENCH_THETA, _WRENCH_THETA)]
    key = (id(config), b"" if theta is None else th.tobytes(), headroom, rotor_check,
           spread.tobytes())
    hit = _KERNEL_CACHE.get(key)
    if hit is not None and hit[0] is config:
        return hit[1]
    lim = config.limits
    # The envelope's ratio bounds: each rotor's own check below implies its rotor bounds.
    thrust = thrust_envelope(config)
    limits = np.array([config.mass, thrust.ratio_min**2, thrust.ratio_max**2, lim.speed_max**2,
                       lim.yaw_acceleration_max, lim.body_rate_max,
                       *(rotor_square_range(config, headroom) if rotor_check
                         else (-UNBOUNDED_SQUARE, UNBOUNDED_SQUARE))])
    # Without the rotor check the A⁺ slabs over the unbounded range (slacks ≈ −1).
    slabs = allocation_slabs(config, limits[6], limits[7], th,
                             None if rotor_check else "pseudo_inverse")
    value = (limits, th[3:6].copy(), slabs.normals,
             np.ascontiguousarray([slabs.lower, slabs.upper, slabs.scale]), spread)
    if len(_KERNEL_CACHE) >= 32:
        _KERNEL_CACHE.clear()
    _KERNEL_CACHE[key] = (config, value)
    return value


def check_segment(
    segment: Segment,
    config: VehicleConfig,
    box: np.ndarray,
    theta: np.ndarray | None = None,
    *,
    grid_step: float = 0.01,
    safety: float = 2.0,
    rotor_headroom: float = 0.0,
    rotor_check: bool = True,
    theta_covariance: np.ndarray | None = None,
    rotor_confidence: float = 0.0,
) -> FeasibilityResult:
    """Check a segment against all limits on the whole of [0, T].

    Parameters
    ----------
    segment : Segment
        The segment.
    config : VehicleConfig
        Mass, rotor geometry and `Limits`.
    box : array_like, shape (6,)
        Flight volume [x_min, y_min, z_min, x_max, y_max, z_max], m, world ENU.
    theta : ndarray, shape (6,), optional
        Parameters for inertia and allocation; the config's nominal θ by default.
    grid_step : float, optional
        Coarse grid step for body rates and rotor speeds, s.
    safety : float, optional
        Factor (≥ 2) on the local bound that decides whether an interval is refined.
    rotor_headroom : float, optional
        Fraction of the rotor n² range kept free at each end (`rotor_square_range`).
    rotor_check : bool, optional
        False leaves out the rotor-speed check (the paper's constraint set).
    theta_covariance : ndarray, shape (6, 6), optional
        Covariance of θ relative to ``theta`` (δθ_j/θ_j). With ``rotor_confidence`` z > 0
        the rotor check is a chance constraint: every slab holds at its value ± z times
        its first-order spread under this covariance (`PlannerSettings.rotor_confidence`).
    rotor_confidence : float, optional
        The one-sided normal quantile z (0: checked at ``theta`` only).

    Returns
    -------
    FeasibilityResult
    """
    T = segment.duration
    which, time, evaluations = _check_kernel(
        segment.derivative_coeffs, T, np.asarray(box, dtype=float),
        _kernel_inputs(config, theta, float(rotor_headroom), bool(rotor_check),
                       theta_covariance, float(rotor_confidence)),
        max(2, ceil(T / grid_step)),
        float(safety))
    if which < 0:
        return FeasibilityResult(True, samples=evaluations)
    return FeasibilityResult(False, CONSTRAINTS[which], time, evaluations)


def segment_slack(segment: Segment, config: VehicleConfig, *, grid_step: float = 0.02,
                  rotor_headroom: float = 0.0, theta_covariance: np.ndarray | None = None,
                  rotor_confidence: float = 0.0) -> float:
    """The segment's largest normalised body-rate or rotor slack on a grid (< 0 inside).

    A smooth measure of how close a segment comes to those limits (for a barrier on
    them), not a feasibility decision: that is `check_segment`'s. Options as there.
    """
    return float(_largest_slack(
        segment.derivative_coeffs, segment.duration, max(2, ceil(segment.duration / grid_step)),
        _kernel_inputs(config, None, float(rotor_headroom), True, theta_covariance,
                       float(rotor_confidence))))


def check_vertex_state(state: VertexState, config: VehicleConfig, box: np.ndarray,
                       theta: np.ndarray | None = None, rotor_headroom: float = 0.0,
                       theta_covariance: np.ndarray | None = None,
                       rotor_confidence: float = 0.0) -> bool:
    """Whether one flat state satisfies every instantaneous limit (for sampling).

    Parameters
    ----------
    state : VertexState
        Position derivatives up to snap and yaw up to yaw acceleration.
    config : VehicleConfig
        Mass, rotor geometry and `Limits`.
    box : array_like, shape (6,)
        Flight volume [x_min, y_min, z_min, x_max, y_max, z_max], m.
    theta : ndarray, shape (6,), optional
        Parameters for inertia and allocation; the config's nominal θ by default.
    rotor_headroom, theta_covariance, rotor_confidence : optional
        As for `check_segment`.

    Returns
    -------
    bool
    """
    # A constant polynomial in the layout of Segment.derivative_coeffs, checked like one.
    dc = np.zeros((10, 18))
    dc[0, :15] = state.position.ravel()
    dc[0, 15:] = state.yaw
    which, _, _ = _check_kernel(dc, 1.0, np.asarray(box, dtype=float),
                                _kernel_inputs(config, theta, float(rotor_headroom), True,
                                               theta_covariance, float(rotor_confidence)),
                                1, 2.0)
    return which < 0
