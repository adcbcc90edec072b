"""Is a trajectory file safe to fly? Checked before connecting, against the vehicle and the box.

The box is the operator's: ``--box``, else the ``[flight] box`` of the vehicle file the
operator chose. Without one nothing flies. A box stored in the trajectory file can only
narrow it (the two boxes' intersection), never widen or move it; the trajectory itself
must lie inside the box in use (`operator_box`).

The limits are the vehicle's (`flight_limits`, from the vehicle config the operator chose,
never from the file's ``limits`` block):

- speed ‖v‖ ≤ ``speed_max``;
- thrust acceleration ‖a − g‖ (collective thrust / mass) within the vehicle's thrust
  envelope (`mavsysid.vehicle.thrust_envelope`): the planner's thrust ratios and the
  rotors' collective thrust at their speed limits, whichever is tighter, [T_min/m, T_max/m];
- jerk ‖j‖ ≤ ``body_rate_max`` · T_max/m: the thrust axis turns at
  ‖j⊥‖/‖a − g‖ ≤ the body-rate limit, and ‖a − g‖ ≤ T_max/m; the same bound is put on
  the whole jerk (the thrust-rate part is far smaller on any flyable trajectory);
- yaw rate |ψ̇| ≤ ``body_rate_max`` (it is a body rate), |ψ̈| ≤ ``yaw_acceleration_max``;
- continuity: position, velocity, acceleration, yaw and yaw rate equal on both sides of
  every segment join (a jump would be sent as one setpoint far away);
- finite values everywhere.

Nothing escapes between samples: each segment is a polynomial, so every quantity's
extreme over the segment is found exactly, at the segment ends or at a real root of its
derivative (squared norms are polynomials too), plus a grid of samples in case a root
is lost to rounding (`mavsysid.vehicle.polynomial_extremes.segment_extremes`, the same
function the planner's and the autopilot's kinematic peaks use). The refusal is one line
naming the quantity, its value, the limit and the time in the file (`check_trajectory`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from mavsysid.flight.ground.setpoints import SetpointLimits
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.polynomial_extremes import segment_extremes
from mavsysid.vehicle.thrust_envelope import thrust_envelope
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import InputError

__all__ = [
    "GROUND_MARGIN",
    "JOIN_TOLERANCE",
    "check_trajectory",
    "flight_limits",
    "format_box",
    "operator_box",
]

#: The streamer's own climb from the ground may go this far below min(z_min, 0), m.
GROUND_MARGIN = 0.5
#: Largest mismatch at a segment join: m, m/s, m/s², rad, rad/s.
JOIN_TOLERANCE = (1e-3, 1e-3, 1e-2, 1e-3, 1e-3)
_P = np.polynomial.polynomial
# The quantities checked (`segment_extremes`' names) and how refusals name them.
_CHECKED = {"x": "x", "y": "y", "z": "z", "speed": "speed",
            "thrust": "thrust acceleration |a - g|", "jerk": "jerk", "yaw": "yaw",
            "yaw_rate": "yaw rate", "yaw_acceleration": "yaw acceleration"}


def _checked_box(box: Sequence[float], source: str) -> tuple[float, ...]:
    b = tuple(float(v) for v in box)
    if len(b) != 6 or not all(np.isfinite(b)) or any(
            lo >= hi for lo, hi in zip(b[:3], b[3:], strict=True)):
        raise InputError(f"{source} {','.join(f'{v:g}' for v in b)}: expected "
                         "x_min,y_min,z_min,x_max,y_max,z_max with each min below its max")
    return b


def format_box(box: Sequence[float]) -> str:
    """``x -2..2, y -2..2, z 0.5..2.5 m``: a box for a one-line message.

    Parameters
    ----------
    box : sequence of 6 float
        [x_min, y_min, z_min, x_max, y_max, z_max], m, world ENU.
    """
    return ", ".join(f"{axis} {box[k]:g}..{box[k + 3]:g}" for k, axis in enumerate("xyz")) \
        + " m"


def operator_box(cli_box: Sequence[float] | None, vehicle_box: Sequence[float] | None,
                 file_box: Sequence[float] | None, path: str) -> tuple[tuple[float, ...], str]:
    """The box to fly in, m, and where it came from.

    The operator's box is ``cli_box`` (``--box``), else ``vehicle_box``: the ``[flight] box``
    of the vehicle file the operator chose (never the configuration embedded in the
    trajectory file, which is the file's). ``file_box``, the trajectory file's own, only
    narrows it: the result is the intersection.

    Parameters
    ----------
    cli_box, vehicle_box, file_box : sequence of 6 float or None
        [x_min, y_min, z_min, x_max, y_max, z_max], m, world ENU.
    path : str
        The trajectory file, for messages.

    Returns
    -------
    box : tuple of 6 float
    source : str
        "--box" or "the vehicle's [flight] box", with "narrowed by the trajectory file's
        box" when the file's box cut it.

    Raises
    ------
    InputError
        No operator box, a box that is not six numbers with each min below its max, or a
        file box that does not overlap the operator's.
    """
    if cli_box is not None:
        box, source = _checked_box(cli_box, "--box"), "--box"
    elif vehicle_box is not None:
        source = "the vehicle's [flight] box"
        box = _checked_box(vehicle_box, source)
    else:
        raise InputError(f"{path}: no flight box from the operator; give --box "
                         "x_min,y_min,z_min,x_max,y_max,z_max or --vehicle with a [flight] box "
                         "(a trajectory file's own box can only narrow it)")
    if file_box is None:
        return box, source
    own = _checked_box(file_box, "the trajectory file's box")
    cut = tuple(max(a, b) for a, b in zip(box[:3], own[:3], strict=True)) + tuple(
        min(a, b) for a, b in zip(box[3:], own[3:], strict=True))
    if any(lo >= hi for lo, hi in zip(cut[:3], cut[3:], strict=True)):
        raise InputError(f"{path}: the trajectory file's box ({format_box(own)}) does not "
                         f"overlap {source} ({format_box(box)})")
    if cut != box:
        source = f"{source} narrowed by the trajectory file's box"
    return cut, source


def flight_limits(config: VehicleConfig, box: Sequence[float]) -> SetpointLimits:
    """The vehicle's limits on a trajectory and on every setpoint (module docstring).

    Parameters
    ----------
    config : VehicleConfig
        The vehicle the operator chose: its `Limits`, mass, rotors and nominal c_T.
    box : sequence of 6 float
        The flight box [x_min, y_min, z_min, x_max, y_max, z_max], m.

    Returns
    -------
    SetpointLimits
    """
    lim = config.limits
    thrust = thrust_envelope(config)
    b = tuple(float(v) for v in box)
    return SetpointLimits(
        box=b, floor=min(b[2], 0.0) - GROUND_MARGIN, speed_max=lim.speed_max,
        thrust_acceleration_min=thrust.minimum, thrust_acceleration_max=thrust.maximum,
        jerk_max=lim.body_rate_max * thrust.maximum, yaw_rate_max=lim.body_rate_max,
        yaw_acceleration_max=lim.yaw_acceleration_max)


def _segment_quantities(pc: np.ndarray, yc: np.ndarray, duration: float
                        ) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, τ, values) of each checked quantity on one segment, at its extreme candidates."""
    extremes = segment_extremes(pc, yc, duration, tuple(_CHECKED))
    return [(label, *extremes[name]) for name, label in _CHECKED.items()]


def _bounds(limits: SetpointLimits) -> dict[str, tuple[float, float, str, str]]:
    """Quantity → (lowest, highest, unit, name of the limit)."""
    b = limits.box
    inf = float("inf")
    return {
        "x": (b[0], b[3], "m", "the box"), "y": (b[1], b[4], "m", "the box"),
        "z": (b[2], b[5], "m", "the box"),
        "speed": (-inf, limits.speed_max, "m/s", "speed_max"),
        "thrust acceleration |a - g|": (limits.thrust_acceleration_min,
                                        limits.thrust_acceleration_max, "m/s²",
                                        "thrust ratios and rotor speeds"),
        "jerk": (-inf, limits.jerk_max, "m/s³", "body_rate_max x thrust"),
        "yaw": (-inf, inf, "rad", ""),
        "yaw rate": (-inf, limits.yaw_rate_max, "rad/s", "body_rate_max"),
        "yaw acceleration": (-inf, limits.yaw_acceleration_max, "rad/s²",
                             "yaw_acceleration_max"),
    }


def _join_problem(trajectory: PiecewisePolynomial) -> str | None:
    """One line for the first segment join where the flight jumps, or None."""
    ends = np.cumsum(trajectory.durations)[:-1]
    if ends.size == 0:
        return None
    names = ("position", "velocity", "acceleration", "yaw", "yaw rate")
    units = ("m", "m/s", "m/s²", "rad", "rad/s")
    for i, t in enumerate(ends):
        left, right = _evaluate(trajectory, i, float(trajectory.durations[i])), \
            _evaluate(trajectory, i + 1, 0.0)
        for name, unit, tol, lv, rv in zip(names, units, JOIN_TOLERANCE, left, right,
                                           strict=True):
            jump = float(np.max(np.abs(np.asarray(lv) - np.asarray(rv))))
            if not jump <= tol:
                return (f"{name} jumps by {jump:.3g} {unit} at the join of segments {i} and "
                        f"{i + 1} (t = {t:.3f} s); at most {tol:g} {unit} is allowed")
    return None


def _evaluate(trajectory: PiecewisePolynomial, i: int, tau: float) -> list[np.ndarray]:
    """Position, velocity, acceleration, yaw, yaw rate of segment ``i`` at local ``tau``."""
    pc, yc = trajectory.position_coeffs[i], trajectory.yaw_coeffs[i]
    out = [np.array([_P.polyval(tau, _P.polyder(c, d)) for c in pc]) for d in range(3)]
    return out + [np.array([_P.polyval(tau, _P.polyder(yc, d))]) for d in range(2)]


def check_trajectory(trajectory: PiecewisePolynomial, limits: SetpointLimits,
                     box_source: str = "the box") -> list[str]:
    """Refusals (one line each; empty: safe) of a trajectory against ``limits``.

    Checks finite values, continuity at the joins, then the box, speed, thrust
    acceleration, jerk, yaw rate and yaw acceleration at their exact extremes over every
    segment. Reports the first problem found, at its worst time in the file.
    """
    with np.errstate(all="ignore"):
        if not (np.all(np.isfinite(trajectory.position_coeffs))
                and np.all(np.isfinite(trajectory.yaw_coeffs))):
            return ["the trajectory has non-finite coefficients"]
        if (problem := _join_problem(trajectory)) is not None:
            return [problem]
        return _limit_problems(trajectory, limits, box_source)


def _limit_problems(trajectory: PiecewisePolynomial, limits: SetpointLimits,
                    box_source: str) -> list[str]:
    bounds = _bounds(limits)
    worst: dict[str, tuple[float, float, float]] = {}  # name → (excess, value, t)
    starts = trajectory.segment_starts
    for i, duration in enumerate(trajectory.durations):
        quantities = _segment_quantities(trajectory.position_coeffs[i],
                                         trajectory.yaw_coeffs[i], float(duration))
        for name, tau, values in quantities:
            lo, hi = bounds[name][:2]
            if not np.all(np.isfinite(values)):
                k = int(np.argmax(~np.isfinite(values)))
                return [f"{name} is not finite at t = {starts[i] + tau[k]:.3f} s"]
            excess = np.maximum(lo - values, values - hi)
            k = int(np.argmax(excess))
            if excess[k] > 1e-9 * max(1.0, abs(hi) if np.isfinite(hi) else 1.0) and (
                    name not in worst or excess[k] > worst[name][0]):
                worst[name] = (float(excess[k]), float(values[k]), float(starts[i] + tau[k]))
    for name, (lo, hi, unit, what) in bounds.items():
        if name not in worst:
            continue
        _, value, t = worst[name]
        if what == "the box":
            side, limit = ("min", lo) if value < lo else ("max", hi)
            return [f"{name} = {value:.3f} m at t = {t:.3f} s is outside {box_source} "
                    f"({name}_{side} {limit:g} m)"]
        limit, word = (lo, "below") if value < lo else (hi, "above")
        return [f"{name} {value:.4g} {unit} at t = {t:.3f} s is {word} the vehicle's limit "
                f"{limit:.4g} {unit} ({what})"]
    return []
