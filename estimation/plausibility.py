"""Is an estimated θ physically possible? Refuse it in one line when it is not.

An estimate is refused (`JobFailedError`, exit 3) when

* a value or its σ is not finite, or the σ is missing;
* c_T, c_D, c_M or a principal moment of J is ≤ 0 (c_D = 0 is a valid *config* value, "no
  rotor drag", but a rotor-drag coefficient *estimated* as ≤ 0 is not a drag: the flight
  did not determine it);
* J breaks the rigid-body triangle inequality j_a + j_b ≥ j_c by more than the slack the
  vehicle configs get (`mavsysid.vehicle.config_checks.INERTIA_TRIANGLE_SLACK`);
* a value is more than `PRIOR_FACTOR_MAX` times above or below the prior (the config's
  nominal value).

An entry the model lets vanish (``may_vanish``; `vanishing_parameters` of the model's
effects: c_D when ``rotor_drag_linear`` carries the rotor drag) may be ≈ 0: a value
within `VANISH_SIGMAS` σ of 0, or any positive value below the prior, is then the right
answer and not refused. Beside a linear rotor drag c_D is the quadratic correction to it
and may be negative as far as physics allows (``floor``, `vanishing_floor`): the rotor
drag k n + c_T c_D n² must stay a drag up to the top rotor speed. (Its σ alone is no
guide there: a filter with k held finds c_D's σ without k's, and the two are nearly
collinear.)

A parameter the prior holds fixed (prior σ = 0, value 0) is the user's choice, not an
estimate, and is not checked. The first problem found is reported, in θ order.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
from mavsysid.vehicle.config import PARAMETER_NAMES, PARAMETER_UNITS
from mavsysid.vehicle.config_checks import INERTIA_TRIANGLE_SLACK, triangle_violation
from mavsysid.vehicle.model_effects import ModelEffect

from mavsysid.errors import JobFailedError

__all__ = ["PRIOR_FACTOR_MAX", "VANISHES_WITH", "VANISH_SIGMAS", "check_plausible",
           "implausibility", "vanishing_floor", "vanishing_parameters"]

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
