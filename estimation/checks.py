"""Refusals of what the data contradict: an impossible θ, a log's wrong clock, a rotor
channel reading wrong.

**An impossible θ** (`check_plausible`, `implausibility`), refused in one line
(`JobFailedError`, exit 3): a value or σ that is not finite or missing; c_T, c_D, c_M or a
principal moment ≤ 0 (c_D = 0 is a valid *config* value, but a drag *estimated* ≤ 0 is not
a drag); J breaking the rigid-body triangle inequality beyond the configs' slack; a value
more than `PRIOR_FACTOR_MAX` times off the prior. An entry the model lets vanish
(`vanishing_parameters`: c_D beside ``rotor_drag_linear``) may be ≈ 0, and as low as keeps
the rotor drag a drag up to the top rotor speed (`vanishing_floor`).

**A wrong clock or position unit** (`check_kinematics`, `tilt_gain`). The thrust points
along the body z axis, so per horizontal axis a_h = λ (a_z + g) b_h / b_z + μ v_h + c
(b = R e_z; drag linear in the velocity and a constant beside it), independent of c_T,
mass and inertia. λ = 1 for a consistent log; a clock s times off scales it by 1/s², a
position in mm read as m by 10⁻³, and the inertia would come out wrong by s² with a small
σ. λ outside [1 / `TIME_SCALE_FACTOR`, `TIME_SCALE_FACTOR`] is refused, when the flight
tilts enough to tell (`MIN_TILT_ACCELERATION`), unless the log's accelerometer says the
clock is right: the horizontal specific force it measures, turned into the world, is the
position's acceleration whatever pushes the vehicle, and a clock s times off scales their
ratio κ (`imu_gain`) by s² too. With κ within `IMU_AGREEMENT` of 1, what the tilt does not
explain is a horizontal force the model lacks (strong wind, drag beyond the model's): that
is said in a note, not refused.

**A rotor channel reading wrong** (`check_rotor_balance`, `rescale_wrong_rotor`). A
vehicle holding its attitude keeps the thrust-weighted centroid of its rotor hubs,
Σ r_i n_i² / Σ n_i², at its centre of gravity, within a few per cent of the arm. A channel
reading half the true speed moves it by a third of the arm or more while the vehicle keeps
flying level: the rotor speeds contradict each other, and a flight whose centroid lies
more than `MAX_CENTROID_OFFSET` off is refused. The one case the data can correct, a
single channel reading a constant share of its speed (a Crazyflie's RPM deck), is rescaled
by the least-squares scale that centres the centroid, and said in a note.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence

import numpy as np
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.signals import (
    SmoothedPose,
    SmootherSettings,
    UniformSegment,
    smooth_pose,
    uniform_segments,
)
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS, VehicleConfig
from mavsysid.vehicle.config_checks import INERTIA_TRIANGLE_SLACK, triangle_violation
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.model_effects import ModelEffect
from scipy.signal import savgol_filter

from mavsysid.errors import JobFailedError

__all__ = ["IMU_AGREEMENT", "MAX_CENTROID_OFFSET", "MIN_TILT_ACCELERATION", "PRIOR_FACTOR_MAX",
           "TIME_SCALE_FACTOR", "VANISHES_WITH", "VANISH_SIGMAS", "check_kinematics",
           "check_plausible", "check_rotor_balance", "implausibility", "imu_gain",
           "rescale_wrong_rotor",
           "thrust_centroid_offset", "tilt_gain", "vanishing_floor", "vanishing_parameters"]


#: An estimate more than this factor above or below its prior is "far outside the prior".
#: Why 10: with the default prior σ of 50 %, a factor 10 above is 18 σ away and a factor 10
#: below is a 90 % drop, which no flight that informs the parameter produces from a sane
#: prior; it is also the signature of a unit or decimal slip (in the config or in the log's
#: motor curve). A rule on σ alone would not do: the filter's σ shrinks on any long log,
#: even when the model does not fit it (wrong answers on real logs come with small σ).
PRIOR_FACTOR_MAX = 10.0

#: θ entries a model effect takes over, so that ≈ 0 is a correct estimate with it in the
#: model: rotor drag linear in rotor speed replaces the paper's quadratic c_D law.
VANISHES_WITH: dict[str, tuple[str, ...]] = {"rotor_drag_linear": ("c_D",)}

#: A vanishing entry may be this many σ below 0 (an unbiased estimate of 0 is negative half
#: the time; 2 σ keeps the false refusals near 2.5 %).
VANISH_SIGMAS = 2.0

_J_FIRST = PARAMETER_NAMES.index("j_x")


def vanishing_parameters(effect_names: Iterable[str]) -> np.ndarray:
    """Which θ entries the model's effects let vanish (`VANISHES_WITH`).

    Parameters
    ----------
    effect_names : iterable of str
        Names of the model effects in the model (``rotor_drag_linear`` …).

    Returns
    -------
    ndarray of bool, shape (6,)
        True for an entry that may be ≈ 0, `PARAMETER_NAMES` order.
    """
    mask = np.zeros(len(PARAMETER_NAMES), bool)
    for name in effect_names:
        for parameter in VANISHES_WITH.get(name, ()):
            mask[PARAMETER_NAMES.index(parameter)] = True
    return mask


def vanishing_floor(effects: Iterable[ModelEffect], c_T: float, rotor_speed_max: float
                    ) -> np.ndarray:
    """The least physically possible value of each θ entry beside ``effects``, SI (6,).

    0 for every entry, except c_D beside ``rotor_drag_linear`` (in-plane k): the rotor
    drag per rotor and unit hub speed, k n + c_T c_D n², stays ≥ 0 for every n up to the
    top rotor speed n_max when c_D ≥ −k / (c_T n_max).

    Parameters
    ----------
    effects : iterable of ModelEffect
        The model's effects at their values.
    c_T : float
        Thrust coefficient, N/(rad/s)².
    rotor_speed_max : float
        Top rotor speed n_max, rad/s.
    """
    floor = np.zeros(len(PARAMETER_NAMES))
    for effect in effects:
        if effect.name == "rotor_drag_linear" and c_T > 0.0 and rotor_speed_max > 0.0:
            floor[PARAMETER_NAMES.index("c_D")] = min(
                0.0, -max(float(effect.values[0]), 0.0) / (c_T * rotor_speed_max))
    return floor


def _vanishes(v: float, s: float | None, floor: float) -> bool:
    """Whether ``v`` ± ``s`` is ≈ 0: positive, within `VANISH_SIGMAS` σ below 0, or not
    below ``floor``."""
    return v > 0.0 or v >= floor or (s is not None and v >= -VANISH_SIGMAS * s)


def _quantity(name: str, value: float, sigma: float | None) -> str:
    unit = PARAMETER_UNITS[name]
    if sigma is None:
        return f"{name} = {value:.3g} {unit}"
    return f"{name} = {value:.3g} ± {sigma:.2g} {unit}"


def _prior_factor(value: float, prior: float) -> str | None:
    """`"79× below the prior 1.02e-07"` when beyond `PRIOR_FACTOR_MAX`, else None."""
    if not prior > 0.0:
        return None
    ratio = value / prior
    if ratio > PRIOR_FACTOR_MAX:
        return f"{ratio:.3g}× above the prior {prior:.3g}"
    if ratio < 1.0 / PRIOR_FACTOR_MAX:
        return f"{1.0 / ratio:.3g}× below the prior {prior:.3g}"
    return None


def _why(sigma: float | None, value: float) -> str:
    # A σ as large as the value means the flight carried no information about it; a small
    # σ means the model was made to fit a log it does not describe.
    if sigma is None or not math.isfinite(sigma):
        return "the log does not determine it"
    if sigma >= 0.5 * abs(value):
        return "the log does not determine it"
    return ("either the vehicle config's prior is wrong or the model does not fit this log "
            "(check --vehicle, its rotor order and, for logs without rotor speeds, the [motor] "
            "curve)")


def implausibility(
    value: Sequence[float] | np.ndarray, sigma: Sequence[float] | np.ndarray | None,
    prior: Sequence[float] | np.ndarray, prior_sigma: Sequence[float] | np.ndarray | None = None,
    may_vanish: Sequence[bool] | np.ndarray | None = None,
    floor: Sequence[float] | np.ndarray | None = None,
) -> str | None:
    """What makes θ physically impossible or implausible, as one phrase; None if nothing.

    Parameters
    ----------
    value : array_like, shape (6,)
        θ in SI units, `PARAMETER_NAMES` order.
    sigma : array_like, shape (6,), or None
        Its standard deviations, SI; None when unknown (then σ is not checked).
    prior : array_like, shape (6,)
        The prior (config's nominal) θ, SI.
    prior_sigma : array_like, shape (6,), optional
        The prior's σ, SI; a parameter with prior σ 0 and value 0 is held, not checked.
    may_vanish : array_like of bool, shape (6,), optional
        Entries the model lets vanish (`vanishing_parameters`): ≤ 0 within `VANISH_SIGMAS`
        σ of 0 or not below ``floor`` is accepted, and so is any value below the prior;
        default none.
    floor : array_like, shape (6,), optional
        Least physically possible value of a vanishing entry (`vanishing_floor`), SI;
        default 0.

    Returns
    -------
    str or None
        E.g. ``"c_M = 1.29e-09 ± 6.6e-09 N·m/(rad/s)² is 79× below the prior 1.02e-07;
        the log does not determine it"``.
    """
    theta = np.asarray(value, dtype=float).reshape(6)
    sig = None if sigma is None else np.asarray(sigma, dtype=float).reshape(6)
    nominal = np.asarray(prior, dtype=float).reshape(6)
    held = np.zeros(6, bool) if prior_sigma is None else (
        (np.asarray(prior_sigma, dtype=float).reshape(6) == 0.0) & (nominal == 0.0))
    vanish = np.zeros(6, bool) if may_vanish is None else np.asarray(may_vanish, bool).reshape(6)
    least = np.zeros(6) if floor is None else np.asarray(floor, float).reshape(6)
    for i, name in enumerate(PARAMETER_NAMES):
        if held[i]:
            continue
        s = None if sig is None else float(sig[i])
        v = float(theta[i])
        if not math.isfinite(v) or (s is not None and not math.isfinite(s)):
            return f"{_quantity(name, v, s)} is not a finite estimate; the filter failed"
        if v <= 0.0 and not (vanish[i] and _vanishes(v, s, float(least[i]))):
            return (f"{_quantity(name, v, s)} is not positive, which is physically "
                    f"impossible; {_why(s, v)}")
    violation = triangle_violation(theta[_J_FIRST:])
    if violation is not None:
        c, a, b = (_J_FIRST + k for k in violation)
        names = PARAMETER_NAMES
        why = _why(None if sig is None else float(sig[c]), float(theta[c]))
        return (f"J = [{theta[3]:.3g}, {theta[4]:.3g}, {theta[5]:.3g}] kg·m² breaks the "
                f"rigid-body triangle inequality ({names[a]} + {names[b]} = "
                f"{theta[a] + theta[b]:.3g} < {names[c]} = {theta[c]:.3g}, more than "
                f"{INERTIA_TRIANGLE_SLACK:.0%} over); {why}")
    for i, name in enumerate(PARAMETER_NAMES):
        far = None if held[i] else _prior_factor(float(theta[i]), float(nominal[i]))
        if far is not None and vanish[i] and theta[i] < nominal[i]:
            far = None  # any value between ≈ 0 and the prior is possible then
        if far is not None:
            s = None if sig is None else float(sig[i])
            return f"{_quantity(name, float(theta[i]), s)} is {far}; {_why(s, float(theta[i]))}"
    return None


def check_plausible(
    source: str, value: Sequence[float] | np.ndarray, sigma: Sequence[float] | np.ndarray | None,
    prior: Sequence[float] | np.ndarray, prior_sigma: Sequence[float] | np.ndarray | None = None,
    what: str = "", may_vanish: Sequence[bool] | np.ndarray | None = None,
    floor: Sequence[float] | np.ndarray | None = None,
) -> None:
    """Raise `JobFailedError` in one line naming ``source`` if θ is implausible.

    Parameters
    ----------
    source : str
        The log (or estimate file) the θ comes from, named first in the message.
    value, sigma, prior, prior_sigma, may_vanish, floor
        As for `implausibility`.
    what : str
        Optional qualifier after the file name (e.g. ``"θ refitted without effects"``).

    Raises
    ------
    JobFailedError
        ``"<source>: [<what>: ]<reason>"``, exit code 3.
    """
    reason = implausibility(value, sigma, prior, prior_sigma, may_vanish, floor)
    if reason is not None:
        head = f"{source}: {what}: " if what else f"{source}: "
        raise JobFailedError(" ".join((head + reason).split()))


#: λ beyond this factor above or below 1 is refused. Why 1.6: a clock 1.27 × off already
#: scales the accelerations (and the inertia estimate) by 1.6 (more than the 50 % an
#: estimate may be off); unmodelled drag, an attitude lagging the position by a few
#: samples and noise move a consistent log's λ by far less (0.96 on the simulated flights
#: of ``bench/fuzz_logs.py``; the ArduCopter SITL and real-log tests are not refused).
TIME_SCALE_FACTOR = 1.6

#: The tilt-predicted horizontal acceleration must vary by at least this RMS, m/s², for λ
#: to be judged: a hovering flight says nothing about its clock this way.
MIN_TILT_ACCELERATION = 0.3

#: Savitzky–Golay window of the tilt check, s: motion-capture noise differentiated twice
#: stays well below the tilt's acceleration, manoeuvres of a few Hz pass.
TILT_WINDOW = 0.3


def _smoothed(segment: UniformSegment) -> tuple[SmoothedPose, int, slice] | None:
    """The segment's pose smoothed as the kinematic checks smooth it, and the rows clear of
    the smoother's one-sided edges; None for a segment too short."""
    settings = SmootherSettings(window=TILT_WINDOW, polyorder=3)
    window = settings.samples(segment.dt)
    if len(segment) < 3 * window:
        return None
    pose = smooth_pose(segment.t, segment.position, segment.quaternion, settings)
    return pose, window, slice(window // 2, len(segment) - window // 2)


def _segment_terms(segment: UniformSegment) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Measured a_h, tilt-predicted a_h and v_h of one uniform segment, each shape (M, 2)."""
    smoothed = _smoothed(segment)
    if smoothed is None:
        return None
    pose, _, cut = smoothed
    a, v, b = pose.acceleration, pose.velocity, pose.rotation()[:, :, 2]
    upright = b[:, 2] > 0.3  # beyond ~70° of tilt the ratio b_h / b_z means nothing
    predicted = (a[:, 2:3] + GRAVITY) * b[:, :2] / np.where(upright, b[:, 2], 1.0)[:, None]
    keep = upright[cut]
    return a[cut, :2][keep], predicted[cut][keep], v[cut, :2][keep]


def _gain(rows: list[np.ndarray], targets: list[np.ndarray]) -> float | None:
    """The first coefficient of the stacked regression, when its column varies enough
    (`MIN_TILT_ACCELERATION`) and everything is finite; None otherwise."""
    if not rows:
        return None
    design, target = np.vstack(rows), np.concatenate(targets)
    if not (np.isfinite(design).all() and np.isfinite(target).all()):
        return None
    centred = design[:, 0] - np.mean(design[:, 0])
    if np.sqrt(np.mean(centred**2)) < MIN_TILT_ACCELERATION:
        return None
    solution, *_ = np.linalg.lstsq(design, target, rcond=None)
    return float(solution[0])


def tilt_gain(flight: FlightData) -> float | None:
    """λ of the module docstring: measured over tilt-predicted horizontal acceleration.

    Returns
    -------
    float or None
        None when the flight does not tilt enough to determine it (or is too short).
    """
    parts = [_segment_terms(s) for s in uniform_segments(flight, 0.0)]
    parts = [x for x in parts if x is not None and x[0].shape[0] > 0]
    rows, targets = [], []
    for s, (a, predicted, v) in enumerate(parts):
        for axis in range(2):
            offsets = np.zeros((a.shape[0], 2 * len(parts)))
            offsets[:, 2 * s + axis] = 1.0  # one constant per segment and axis
            rows.append(np.column_stack([predicted[:, axis], v[:, axis], offsets]))
            targets.append(a[:, axis])
    return _gain(rows, targets)


#: κ (`imu_gain`) within this share of 1 says the clock and position unit are right.
IMU_AGREEMENT = 0.15


def imu_gain(flight: FlightData) -> float | None:
    """κ of the module docstring: the accelerometer's horizontal specific force, turned into
    the world, over the position's horizontal acceleration (both smoothed alike).

    Parameters
    ----------
    flight : FlightData
        Pose and, in ``imu``, the accelerometer (body FLU specific force).

    Returns
    -------
    float or None
        None without an accelerometer, or when the flight does not accelerate enough.
    """
    imu = flight.imu
    if imu is None or imu.accel is None or len(imu.accel) < 2:
        return None
    rows, targets = [], []
    segments = list(uniform_segments(flight, 0.0))
    for index, segment in enumerate(segments):
        smoothed = _smoothed(segment)
        if smoothed is None:
            continue
        pose, window, cut = smoothed
        force = np.column_stack([np.interp(segment.t, imu.accel.t, imu.accel.values[:, i])
                                 for i in range(3)])
        world = savgol_filter(np.einsum("nij,nj->ni", pose.rotation(), force), window, 3,
                              axis=0)
        for axis in range(2):
            offsets = np.zeros((len(segment), 2 * len(segments)))
            offsets[:, 2 * index + axis] = 1.0  # an accelerometer bias per segment and axis
            rows.append(np.column_stack([pose.acceleration[:, axis], offsets])[cut])
            targets.append(world[cut, axis])
    return _gain(rows, targets)


def check_kinematics(flight: FlightData) -> str | None:
    """Refuse, in one line naming the log, a flight whose motion contradicts its attitude.

    Returns
    -------
    str or None
        A note where the tilt does not explain the motion but the accelerometer agrees
        with the position (`imu_gain`): a horizontal force the model lacks.

    Raises
    ------
    JobFailedError
        λ (`tilt_gain`) outside [1 / `TIME_SCALE_FACTOR`, `TIME_SCALE_FACTOR`], and no
        accelerometer that says the clock is right.
    """
    gain = tilt_gain(flight)
    if gain is None or 1.0 / TIME_SCALE_FACTOR <= gain <= TIME_SCALE_FACTOR:
        return None
    kappa = imu_gain(flight)
    if kappa is not None and abs(kappa - 1.0) <= IMU_AGREEMENT:
        return (f"{flight.source}: the horizontal acceleration of the logged position is "
                f"{gain:.3g} × what the logged tilt demands, and the accelerometer agrees "
                f"with the position ({kappa:.3g} ×): a horizontal force the model lacks "
                "pushes the vehicle (strong wind, or drag beyond the model's); mavsysid "
                "diagnose names it")
    raise JobFailedError(
        f"{flight.source}: the horizontal acceleration of the logged position is {gain:.3g} × "
        "what the logged tilt demands (thrust along the body z axis; expected about 1): the "
        "log's clock or position unit is wrong (a clock s × too slow scales it by 1/s²), so "
        "its motion contradicts its attitude and θ cannot be estimated from it")


#: Largest offset of the thrust centroid from the rotors' centre, as a share of the arm.
MAX_CENTROID_OFFSET = 0.2


def thrust_centroid_offset(rotor_speeds: np.ndarray, config: VehicleConfig) -> np.ndarray:
    """Median thrust-weighted hub centroid relative to the rotors' centre, in arms, (2,).

    Parameters
    ----------
    rotor_speeds : ndarray, shape (N, k)
        rad/s.
    config : VehicleConfig
        Rotor positions.
    """
    r = config.rotor_positions[:, :2]
    centre = r.mean(axis=0)
    arm = float(np.mean(np.linalg.norm(r - centre, axis=1)))
    n2 = np.asarray(rotor_speeds, float) ** 2
    total = n2.sum(axis=1)
    flying = total > 0.0
    centroid = (n2[flying] @ (r - centre)) / total[flying, None]
    return np.median(centroid, axis=0) / arm if flying.any() else np.zeros(2)


def check_rotor_balance(flight: FlightData, config: VehicleConfig,
                        max_offset: float = MAX_CENTROID_OFFSET) -> None:
    """Refuse, in one line, rotor speeds that put the thrust centroid far off centre.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
    max_offset : float
        Share of the arm.

    Raises
    ------
    JobFailedError
        Naming the offset and the rotor whose median speed is furthest below the others'.
    """
    offset = thrust_centroid_offset(flight.rotor_speeds, config)
    size = float(np.hypot(*offset))
    if size <= max_offset:
        return
    median = np.median(flight.rotor_speeds, axis=0)
    ratio = median / np.median(median)
    worst = int(np.argmin(ratio))
    raise JobFailedError(
        f"{flight.source}: the rotor speeds put the thrust centroid {100 * size:.0f} % of the "
        f"arm off the rotors' centre while the vehicle holds its attitude (at most "
        f"{100 * max_offset:.0f} % expected); rotor {worst + 1}'s median speed is "
        f"{100 * ratio[worst]:.0f} % of the rotors' median: a rotor-speed channel reading "
        "wrong, or a centre of gravity far off the rotors' centre")


def rescale_wrong_rotor(flight: FlightData, config: VehicleConfig,
                        max_offset: float = MAX_CENTROID_OFFSET
                        ) -> tuple[FlightData, str | None]:
    """The flight with one rotor channel rescaled when it alone puts the centroid off centre.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
        Rotor positions.
    max_offset : float
        Share of the arm.

    Returns
    -------
    flight : FlightData
        Unchanged when the centroid is within ``max_offset`` or no single-rotor scale brings
        it there (then `check_rotor_balance` refuses it); else with the rotor's speeds, at
        the pose's rows and as logged (``inputs``), multiplied by s.
    note : str or None
        What was corrected, and why.
    """
    offset = thrust_centroid_offset(flight.rotor_speeds, config)
    if float(np.hypot(*offset)) <= max_offset:
        return flight, None
    n = np.asarray(flight.rotor_speeds, float)
    median = np.median(n, axis=0)
    if not np.median(median) > 0.0:
        return flight, None
    worst = int(np.argmin(median / np.median(median)))
    r = config.rotor_positions[:, :2]
    r = r - r.mean(axis=0)
    n2 = n**2
    use = (n2.sum(axis=1) > 0.0) & (n[:, worst] > 0.0)
    a = n2[use, worst, None] * r[worst]
    b = n2[use] @ r
    denominator = float(np.sum(a * a))
    if not denominator > 0.0:
        return flight, None
    scale_sq = 1.0 - float(np.sum(a * b)) / denominator
    if not scale_sq > 0.0:
        return flight, None
    scale = float(np.sqrt(scale_sq))
    corrected = n.copy()
    corrected[:, worst] *= scale
    if float(np.hypot(*thrust_centroid_offset(corrected, config))) > max_offset:
        return flight, None
    note = (f"{flight.source}: rotor {worst + 1}'s speeds put the thrust centroid "
            f"{100 * float(np.hypot(*offset)):.0f} % of the arm off the rotors' centre while "
            f"the vehicle holds its attitude; its channel reads {100 / scale:.0f} % of the "
            f"speed that balances the others and was multiplied by {scale:.3g} (a rotor-speed "
            "channel reading a constant share; check its sensor)")
    inputs = None if flight.inputs is None else flight.inputs.scaled(worst, scale)
    return dataclasses.replace(flight, rotor_speeds=corrected, inputs=inputs,
                               warnings=(*flight.warnings, note)), note
