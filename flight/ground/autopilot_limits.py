"""The autopilot's position-controller limits, checked against a plan before take-off.

ArduCopter in GUIDED with position, velocity and acceleration targets
(``ModeGuided::posvelaccel_control_run`` → ``AC_PosControl::input_pos_vel_accel_NE_m``
with ``limit_output = false``, source at ArduPilot 90700977) passes the feed-forward
through, but:

- the total acceleration target changes at most at the jerk limit, ``PSC_JERK_XY`` /
  ``PSC_JERK_Z`` (m/s³), which ``set_max_speed_accel_NE_m`` further caps at
  ½ √(``WPNAV_ACCEL`` · g · min(``ATC_ACCEL_R_MAX``, ``ATC_ACCEL_P_MAX``)) (cm/s², cdeg/s²);
- the horizontal acceleration is cut at the lean angle ``ANGLE_MAX`` (cdeg), or
  ``PSC_ANGLE_MAX`` (deg) when that is > 0;
- the yaw rate is clamped to ``ATC_SLEW_YAW`` (cdeg/s) and ``ATC_RATE_Y_MAX`` (deg/s, 0 =
  none), the yaw acceleration shaped by ``ATC_ACCEL_Y_MAX`` (cdeg/s², 0 = none).

Those are *tracking* limits: a plan beyond them is refused. ``WPNAV_SPEED``,
``WPNAV_SPEED_UP``, ``WPNAV_SPEED_DN`` (cm/s), ``WPNAV_ACCEL`` and ``WPNAV_ACCEL_Z`` (cm/s²)
only bound the correction back to the path in that mode (`correction` limits): a plan
beyond them is flown, with a note. PX4 (``MPC_*``, m/s, m/s², m/s³, deg, deg/s) is checked
the same way (`PX4_LIMITS` says which are tracking limits).

With ``--set-limits`` (`apply_autopilot_limits` with ``raise_limits``) every limit below
the plan, tracking or correction, is raised for the flight to the peak plus `MARGIN`,
never above the parameter's cap (a plan above a cap is refused), through a
`ParameterSession` that the flight restores at its end, failure or interruption.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.parameter_session import ParameterSession
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.kinematic_limits import (
    KINEMATIC_WORDS,
    KinematicLimits,
    KinematicPeaks,
    kinematic_peaks,
)
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import InputError, JobFailedError

__all__ = ["ARDUPILOT_LIMITS", "MARGIN", "PX4_LIMITS", "LimitParameter", "Requirement",
           "apply_autopilot_limits", "check_session_limits", "continuation_limit_refusals",
           "kinematic_limits", "limit_parameters", "limits_from_parameters", "limits_in_effect",
           "limits_text", "parameter_names", "raised_values", "refusal", "requirements"]

#: Raised limits leave this much above the plan's peak (relative).
MARGIN = 0.2
_CDEG = math.radians(0.01)


@dataclass(frozen=True)
class LimitParameter:
    """One autopilot parameter that limits what the position controller follows.

    Attributes
    ----------
    name : str
    quantities : tuple of str
        The `KinematicPeaks` fields it bounds.
    scale : float
        SI value of one parameter unit (0.01 for cm/s, π/18000 for cdeg, …).
    unit : str
        The parameter's own unit, for messages.
    cap : float
        Highest value `raised_values` writes, parameter units.
    tracking : bool
        A plan beyond it cannot be tracked (else it bounds the correction only).
    zero_unlimited : bool
        A value ≤ 0 means no limit.
    integer : bool
        Stored as an integer.
    """

    name: str
    quantities: tuple[str, ...]
    scale: float
    unit: str
    cap: float
    tracking: bool = True
    zero_unlimited: bool = False
    integer: bool = False


#: ArduCopter (units and meaning from its parameter docs; caps: the documented @Range
#: maximum, except WPNAV_ACCEL (range 50–500) at 1000 cm/s², the acceleration of a 45°
#: lean, and the lean angles at 60°).
ARDUPILOT_LIMITS = (
    LimitParameter("WPNAV_SPEED", ("speed_xy",), 0.01, "cm/s", 2000.0, tracking=False),
    LimitParameter("WPNAV_SPEED_UP", ("climb",), 0.01, "cm/s", 1000.0, tracking=False),
    LimitParameter("WPNAV_SPEED_DN", ("descent",), 0.01, "cm/s", 500.0, tracking=False),
    LimitParameter("WPNAV_ACCEL", ("accel_xy",), 0.01, "cm/s²", 1000.0, tracking=False),
    LimitParameter("WPNAV_ACCEL_Z", ("accel_up", "accel_down"), 0.01, "cm/s²", 500.0,
                   tracking=False),
    LimitParameter("PSC_JERK_XY", ("jerk_xy",), 1.0, "m/s³", 20.0),
    LimitParameter("PSC_JERK_Z", ("jerk_z",), 1.0, "m/s³", 50.0),
    LimitParameter("ANGLE_MAX", ("tilt",), _CDEG, "cdeg", 6000.0, integer=True),
    LimitParameter("PSC_ANGLE_MAX", ("tilt",), math.radians(1.0), "deg", 60.0,
                   zero_unlimited=True),
    LimitParameter("ATC_SLEW_YAW", ("yaw_rate",), _CDEG, "cdeg/s", 18000.0),
    LimitParameter("ATC_RATE_Y_MAX", ("yaw_rate",), math.radians(1.0), "deg/s", 1080.0,
                   zero_unlimited=True),
    LimitParameter("ATC_ACCEL_Y_MAX", ("yaw_acceleration",), _CDEG, "cdeg/s²", 72000.0,
                   zero_unlimited=True),
)
#: Read with ArduPilot's limits: the roll/pitch angular accelerations that cap the jerk.
_ARDUPILOT_EXTRA = ("ATC_ACCEL_R_MAX", "ATC_ACCEL_P_MAX", "ATC_RATE_FF_ENAB")

#: PX4 (caps: the documented maxima, the tilt at 60°, the yaw rate at 360°/s). Its
#: position control clamps the velocity setpoint, feed-forward included, to the
#: MPC_*_VEL_MAX* and the tilt to MPC_TILTMAX_AIR; the acceleration, jerk and auto yaw-rate
#: limits shape its own trajectory generators, not an offboard setpoint (correction only).
PX4_LIMITS = (
    LimitParameter("MPC_XY_VEL_MAX", ("speed_xy",), 1.0, "m/s", 20.0),
    LimitParameter("MPC_Z_VEL_MAX_UP", ("climb",), 1.0, "m/s", 8.0),
    LimitParameter("MPC_Z_VEL_MAX_DN", ("descent",), 1.0, "m/s", 4.0),
    LimitParameter("MPC_ACC_HOR_MAX", ("accel_xy",), 1.0, "m/s²", 15.0, tracking=False),
    LimitParameter("MPC_ACC_UP_MAX", ("accel_up",), 1.0, "m/s²", 15.0, tracking=False),
    LimitParameter("MPC_ACC_DOWN_MAX", ("accel_down",), 1.0, "m/s²", 15.0, tracking=False),
    LimitParameter("MPC_JERK_MAX", ("jerk",), 1.0, "m/s³", 80.0, tracking=False),
    LimitParameter("MPC_JERK_AUTO", ("jerk",), 1.0, "m/s³", 80.0, tracking=False),
    LimitParameter("MPC_TILTMAX_AIR", ("tilt",), math.radians(1.0), "deg", 60.0),
    LimitParameter("MPC_YAWRAUTO_MAX", ("yaw_rate",), math.radians(1.0), "deg/s", 360.0,
                   tracking=False),
)


def limit_parameters(autopilot: Autopilot) -> tuple[LimitParameter, ...]:
    """The limit parameters of ``autopilot``."""
    return ARDUPILOT_LIMITS if autopilot is Autopilot.ARDUPILOT else PX4_LIMITS


def parameter_names(autopilot: Autopilot) -> list[str]:
    """Every parameter `requirements` reads for ``autopilot``."""
    names = [p.name for p in limit_parameters(autopilot)]
    return names + list(_ARDUPILOT_EXTRA) if autopilot is Autopilot.ARDUPILOT else names


def _jerk_snap(values: Mapping[str, float]) -> float | None:
    """ArduPilot's g · min(ATC_ACCEL_R_MAX, ATC_ACCEL_P_MAX), m/s⁴, or None when off."""
    r, p = values.get("ATC_ACCEL_R_MAX"), values.get("ATC_ACCEL_P_MAX")
    if r is None or p is None or r <= 0.0 or p <= 0.0 or values.get("ATC_RATE_FF_ENAB", 1) == 0:
        return None
    return GRAVITY * min(r, p) * _CDEG


def kinematic_limits(autopilot: Autopilot, values: Mapping[str, float],
                     tracking_only: bool = False) -> KinematicLimits:
    """The envelope the parameter ``values`` set, SI (the smallest bound of each quantity).

    Parameters
    ----------
    autopilot : Autopilot
    values : mapping
        Parameter name → value in its own unit; absent names bound nothing.
    tracking_only : bool
        Leave out ArduPilot's correction limits (WPNAV_*).
    """
    bounds: dict[str, float] = {}
    for spec in limit_parameters(autopilot):
        value = values.get(spec.name)
        if value is None or (spec.zero_unlimited and value <= 0.0):
            continue
        if tracking_only and not spec.tracking:
            continue
        for q in spec.quantities:
            bounds[q] = min(bounds.get(q, math.inf), value * spec.scale)
    snap = _jerk_snap(values) if autopilot is Autopilot.ARDUPILOT else None
    if snap is not None and "WPNAV_ACCEL" in values:
        cap = 0.5 * math.sqrt(max(values["WPNAV_ACCEL"], 0.0) * 0.01 * snap)
        bounds["jerk_xy"] = min(bounds.get("jerk_xy", math.inf), cap)
    return KinematicLimits(**bounds)


def limits_from_parameters(values: Mapping[str, float], source: str
                           ) -> tuple[Autopilot, KinematicLimits]:
    """The autopilot a parameter dump is of, and the envelope its limits set
    (`kinematic_limits`, correction limits included: a plan within them flies with no
    note).

    Raises
    ------
    InputError
        A dump with none of either autopilot's limit parameters, or with both (one line
        naming ``source``).
    """
    found = {a: [p.name for p in limit_parameters(a) if p.name in values]
             for a in (Autopilot.ARDUPILOT, Autopilot.PX4)}
    mine = [a for a, names in found.items() if names]
    if len(mine) != 1:
        wanted = ", ".join(p.name for p in ARDUPILOT_LIMITS[:3] + PX4_LIMITS[:2])
        raise InputError(f"{source}: " + ("holds both ArduPilot and PX4 limit parameters"
                         if mine else f"holds none of the autopilot's position-controller "
                         f"limits ({wanted}, …); a defaults file leaves them unset: save them "
                         "from the running vehicle, or read them from it with "
                         "--connect LINK"))
    return mine[0], kinematic_limits(mine[0], values)


@dataclass(frozen=True)
class Requirement:
    """What a plan needs of one parameter: its current and its needed value (its units)."""

    name: str
    current: float
    needed: float
    unit: str
    tracking: bool
    what: str

    def line(self) -> str:
        """``NAME current < needed unit (what)``."""
        return (f"{self.name} {self.current:g} < {_shown(self.needed)} {self.unit} "
                f"({self.what})")


def _shown(value: float) -> str:
    return f"{value:.3g}" if value < 100.0 else f"{value:.0f}"


def requirements(autopilot: Autopilot, peaks: KinematicPeaks,
                 values: Mapping[str, float]) -> list[Requirement]:
    """Every limit in ``values`` that is below what the plan's ``peaks`` need.

    A parameter the vehicle does not report, or a zero that means "no limit", needs
    nothing. ArduPilot's WPNAV_ACCEL also caps the horizontal jerk (module docstring):
    that need is a tracking one.
    """
    out = []
    for spec in limit_parameters(autopilot):
        current = values.get(spec.name)
        if current is None or (spec.zero_unlimited and current <= 0.0):
            continue
        q = max(spec.quantities, key=lambda name: getattr(peaks, name))
        needed = getattr(peaks, q) / spec.scale
        if current < needed:
            out.append(Requirement(spec.name, current, needed, spec.unit, spec.tracking,
                                   f"peak {KINEMATIC_WORDS[q]} {_peak_text(q, getattr(peaks, q))}"))
    snap = _jerk_snap(values) if autopilot is Autopilot.ARDUPILOT else None
    current = values.get("WPNAV_ACCEL")
    if snap is not None and current is not None:
        needed = 4.0 * peaks.jerk_xy**2 / snap / 0.01
        if current < needed:
            out.append(Requirement("WPNAV_ACCEL", current, needed, "cm/s²", True,
                                   f"caps the jerk below the peak {peaks.jerk_xy:.3g} m/s³"))
    return out


def _peak_text(quantity: str, value: float) -> str:
    if quantity == "tilt":
        return f"{math.degrees(value):.1f}°"
    if quantity.startswith("yaw"):
        return f"{math.degrees(value):.0f}°/s" + ("²" if quantity.endswith("acceleration")
                                                   else "")
    unit = {"speed": "m/s", "accel": "m/s²", "jerk": "m/s³"}
    head = "speed" if quantity in ("speed_xy", "climb", "descent") else quantity.split("_")[0]
    return f"{value:.3g} {unit[head]}"


def limits_text(limits: KinematicLimits) -> str:
    """The limited quantities of an envelope, in words with SI units (one line).

    Parameters
    ----------
    limits : KinematicLimits
        The envelope: speeds in m/s, accelerations in m/s², jerks in m/s³, tilt in rad,
        yaw rate in rad/s and yaw acceleration in rad/s²; a None field is unlimited and
        left out ("none" when all are).
    """
    shown = [f"{KINEMATIC_WORDS[name]} {_peak_text(name, value)}"
             for name, value in vars(limits).items() if value is not None]
    return ", ".join(shown) if shown else "none"


def refusal(needs: list[Requirement]) -> str:
    """The one-line refusal of a plan the tracking limits cannot follow."""
    shown = "; ".join(r.line() for r in needs)
    return (f"flight refused: the autopilot's limits are below the plan: {shown}; raise "
            "them, fly with --set-limits, or plan with --autopilot-limits")


def raised_values(autopilot: Autopilot, needs: list[Requirement],
                  margin: float = MARGIN) -> dict[str, float]:
    """Parameter → value for the flight: the need plus ``margin``, at most the cap.

    Raises
    ------
    JobFailedError
        A need above a parameter's cap (one line with the names and numbers).
    """
    specs = {p.name: p for p in limit_parameters(autopilot)}
    need: dict[str, float] = {}
    for r in needs:
        need[r.name] = max(need.get(r.name, 0.0), r.needed)
    over = [f"{n} {_shown(v)} {specs[n].unit} (cap {specs[n].cap:g})"
            for n, v in need.items() if v > specs[n].cap]
    if over:
        raise JobFailedError("flight refused: --set-limits would raise the autopilot's "
                             f"limits above their sane caps: {'; '.join(over)}")
    out = {}
    for name, value in need.items():
        spec = specs[name]
        target = min(value * (1.0 + margin), spec.cap)
        step = 1.0 if spec.integer or spec.scale < 0.1 else 0.1
        out[name] = min(math.ceil(target / step - 1e-9) * step, spec.cap)
    return out


def apply_autopilot_limits(parameters: ParameterSession, autopilot: Autopilot,
                           peaks: KinematicPeaks, raise_limits: bool,
                           say: Callable[[str], None]) -> dict[str, float]:
    """Read the autopilot's limits; refuse, note, or raise them for the flight.

    Parameters
    ----------
    parameters : ParameterSession
        The flight's parameter session (its `restore` puts raised limits back).
    autopilot : Autopilot
    peaks : KinematicPeaks
        The trajectory's (`mavsysid.vehicle.kinematic_limits.kinematic_peaks`).
    raise_limits : bool
        ``--set-limits``: raise every limit below the plan instead of refusing.
    say : callable
        Receives one-line progress messages.

    Returns
    -------
    dict
        The values read (parameter units).

    Raises
    ------
    JobFailedError
        Tracking limits below the plan (without ``raise_limits``), a need above a cap,
        or a parameter the vehicle would not set.
    """
    values = parameters.read(parameter_names(autopilot))
    known = [p.name for p in limit_parameters(autopilot) if p.name in values]
    if not known:
        say("warning: the vehicle reports none of its position-controller limits; "
            "the plan is not checked against them")
        return values
    needs = requirements(autopilot, peaks, values)
    if raise_limits and needs:
        new = raised_values(autopilot, needs)
        for name, value in new.items():
            parameters.set(name, value)
        say("autopilot limits raised for the flight: " + ", ".join(
            f"{n} {values[n]:g} → {v:g}" for n, v in new.items()))
        return values
    hard = [r for r in needs if r.tracking]
    if hard:
        raise JobFailedError(refusal(hard))
    soft = [r for r in needs if not r.tracking]
    if soft:
        say("note: the plan is beyond the autopilot's correction limits (it corrects "
            "back to the path more gently): " + "; ".join(r.line() for r in soft))
    else:
        say(f"autopilot limits: the plan is within {', '.join(known)}")
    return values


def check_session_limits(session: Any, say: Callable[[str], None]) -> None:
    """`apply_autopilot_limits` for a `StreamSession` (``settings.set_limits``), before
    arming; the values read and the plan's peaks go into ``meta.json``
    (``autopilot_limits``); raised ones are restored with the session's parameters."""
    peaks = kinematic_peaks(session.trajectory)
    values = apply_autopilot_limits(session.parameters, session.link.vehicle.autopilot,
                                    peaks, bool(session.settings.set_limits), say)
    session.note("autopilot_limits", {
        "read": values, "set_limits": bool(session.settings.set_limits),
        "plan_peaks_si": {k: round(v, 6) for k, v in asdict(peaks).items()}})


def limits_in_effect(noted: Mapping[str, Any] | None,
                     changed: Mapping[str, tuple[float, float]]) -> dict[str, float] | None:
    """The autopilot's position-controller limits now (parameter units): the values read
    before arming (``noted``, meta.json's ``autopilot_limits``) with the flight values of
    those ``--set-limits`` raised (``ParameterSession.changed``); None if none were read."""
    if not noted or not noted.get("read"):
        return None
    values = dict(noted["read"])
    values.update({name: flight for name, (_orig, flight) in changed.items() if name in values})
    return values


def continuation_limit_refusals(autopilot: Autopilot, values: Mapping[str, float],
                                trajectory: PiecewisePolynomial) -> list[str]:
    """Why a trajectory planned in flight exceeds the tracking limits ``values`` (one line,
    or none).

    Mid-flight the limits are never raised: a continuation beyond them is refused (and
    the vehicle lands) rather than flown off its path.
    """
    hard = [r for r in requirements(autopilot, kinematic_peaks(trajectory), values)
            if r.tracking]
    return [refusal(hard)] if hard else []
