"""The motor curve: rotor speed ↔ the motor output an autopilot logs, both ways.

A log that has no ESC rpm still has what the autopilot sent to the motors: a PWM pulse
width or a normalised output. With throttle u in [0, 1] and ArduPilot's MOT_THST_EXPO
(PX4's THR_MDL_FAC has the same meaning) e, thrust ∝ (1 − e) u + e u², and thrust ∝ n², so

    n = rotor_speed_max · sqrt((1 − e) u + e u²).

Readers of logs (`mavsysid.formats.tlog`, `mavsysid.formats.ulog`,
`mavsysid.formats.dataflash`) apply it to motor outputs; writers of simulated logs
(`mavsysid.flight.offline`) apply its inverse to commanded rotor speeds. This is a
commanded speed through a nominal curve, not a measured one: the `[motor]` keys of the
vehicle config (``pwm_min``, ``pwm_max``, ``thrust_expo``) set it.

The curve holds at one battery voltage. At a given output a motor turns as fast as its
back-EMF balances the voltage the output applies, so its speed goes as the supply
voltage: n(V) = n · V / V_ref. Where the vehicle file states V_ref (``[motor] voltage``)
and the log has the battery's voltage, `battery_scale` gives that factor per output sample;
where it does not and the battery fell in flight, it says how far the commanded speeds are
off (a 10 % sag is 19 % of thrust at the same output).

A log with ESC rpm too sparse to be the rotor speeds still measures the curve's scale
(`fit_curve_scale`): the readers' callers take the curve times that scale, with its σ, and
refuse a curve too far off to be these motors' (`check_curve_against_rpm`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.formats.parsed_log import Series
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import LogFormatError

__all__ = ["CURVE_RPM_TOLERANCE", "VOLTAGE_SAG_NOTE", "CurveScale", "battery_scale",
           "check_curve_against_rpm", "check_pwm_outputs", "commanded_rotor_speeds",
           "describe_curve", "fit_curve_scale", "on_battery",
           "pwm_curve_caveat", "pwm_from_rotor_speed", "rotor_speed_from_pwm",
           "rotor_speed_from_throttle", "throttle_from_pwm", "throttle_from_rotor_speed"]


def throttle_from_pwm(pwm: np.ndarray, pwm_min: float, pwm_max: float) -> np.ndarray:
    """Throttle u from a PWM pulse width.

    Parameters
    ----------
    pwm : array_like, any shape
        Motor output pulse width, µs. 0 (an output that is off) gives u = 0.
    pwm_min, pwm_max : float
        Pulse widths of zero and full throttle, µs, ``pwm_min < pwm_max``.

    Returns
    -------
    ndarray, same shape
        u in [0, 1] (values outside the PWM range are clipped).
    """
    u = (np.asarray(pwm, dtype=float) - pwm_min) / (pwm_max - pwm_min)
    return np.clip(u, 0.0, 1.0)


def rotor_speed_from_throttle(u: np.ndarray, rotor_speed_max: float,
                              thrust_expo: float) -> np.ndarray:
    """Rotor speed from throttle through the thrust curve.

    Parameters
    ----------
    u : array_like, any shape
        Throttle, clipped to [0, 1]. NaN stays NaN (PX4 marks unused motors so).
    rotor_speed_max : float
        Rotor speed at full throttle, rad/s.
    thrust_expo : float
        e in [0, 1]: thrust ∝ (1 − e) u + e u².

    Returns
    -------
    ndarray, same shape
        n = rotor_speed_max · sqrt((1 − e) u + e u²), rad/s.
    """
    u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    return rotor_speed_max * np.sqrt((1.0 - thrust_expo) * u + thrust_expo * u * u)


def rotor_speed_from_pwm(pwm: np.ndarray, vehicle: VehicleConfig) -> np.ndarray:
    """Rotor speed from PWM with the vehicle's `[motor]` curve.

    Parameters
    ----------
    pwm : array_like, any shape
        Motor output pulse width, µs.
    vehicle : VehicleConfig
        ``[motor]`` pwm_min, pwm_max, thrust_expo and ``[limits]`` rotor_speed_max.

    Returns
    -------
    ndarray, same shape
        Rotor speed, rad/s.
    """
    motor = vehicle.motor
    u = throttle_from_pwm(pwm, motor.pwm_min, motor.pwm_max)
    return rotor_speed_from_throttle(u, vehicle.limits.rotor_speed_max, motor.thrust_expo)


#: Share of the vehicle's PWM span an armed output may lie outside it (an idle below
#: ``pwm_min``, a trimmed top above ``pwm_max``).
PWM_MARGIN = 0.1

#: Share of the outputs above ``pwm_min`` that may lie above the widened span.
PWM_OUTSIDE_SHARE = 0.05


def check_pwm_outputs(pwm: np.ndarray, vehicle: VehicleConfig, where: str) -> None:
    """Refuse motor outputs that are not PWM in the vehicle's ``[motor]`` range.

    Rotor speeds through the motor curve are only as right as its range: outputs in
    another unit (a mixer's 0..1, a 12-bit scale) would be clipped into a made-up thrust,
    and c_T with them. Outputs below the range are left to the hover check
    (`mavsysid.estimation.readers.samples`): a disarmed level (0, PX4's 900 µs) or an
    idle is PWM too. Outputs that never reach half of ``pwm_min`` are no PWM at all.

    Parameters
    ----------
    pwm : ndarray, shape (N, k)
        The logged motor outputs, µs as the log says.
    vehicle : VehicleConfig
        ``[motor]`` pwm_min and pwm_max.
    where : str
        The log and message, for the message.

    Raises
    ------
    LogFormatError
        More than `PWM_OUTSIDE_SHARE` of the outputs above ``pwm_min`` lie above the range
        widened by `PWM_MARGIN` of its span, or none reaches half of ``pwm_min``; one line.
    """
    values = np.asarray(pwm, dtype=float)
    values = values[np.isfinite(values) & (values != 0.0)]
    if values.size == 0:
        return
    low, high = vehicle.motor.pwm_min, vehicle.motor.pwm_max
    running = values[values > low]
    above = float(np.mean(running > high + PWM_MARGIN * (high - low))) if running.size else 0.0
    if np.max(values) >= 0.5 * low and above <= PWM_OUTSIDE_SHARE:
        return
    lo, hi = np.percentile(values, [5, 95])
    raise LogFormatError(
        f"{where}: the motor outputs are not PWM in the vehicle's [motor] range "
        f"{low:g}–{high:g} µs (5–95 % of the non-zero ones at {lo:.4g}–{hi:.4g}): rotor "
        "speeds through the motor curve would be made up; log ESC rpm, or set [motor] "
        "pwm_min and pwm_max to what the vehicle sends")


def throttle_from_rotor_speed(n: np.ndarray, rotor_speed_max: float,
                              thrust_expo: float) -> np.ndarray:
    """Throttle u for rotor speeds n: the inverse of `rotor_speed_from_throttle`.

    Thrust ∝ (1 − e) u + e u² ∝ n², so u solves e u² + (1 − e) u − (n / n_max)² = 0.

    Parameters
    ----------
    n : array_like, any shape
        Rotor speeds, rad/s (clipped to [0, rotor_speed_max]).
    rotor_speed_max : float
        Rotor speed at full throttle, rad/s.
    thrust_expo : float
        e in [0, 1].

    Returns
    -------
    ndarray, same shape
        u in [0, 1]; with e = 0 the relative thrust (n / n_max)².
    """
    e = thrust_expo
    s = np.clip(np.asarray(n, dtype=float) / rotor_speed_max, 0.0, 1.0) ** 2
    return s if e == 0.0 else (-(1.0 - e) + np.sqrt((1.0 - e) ** 2 + 4.0 * e * s)) / (2.0 * e)


def pwm_from_rotor_speed(n: np.ndarray, vehicle: VehicleConfig) -> np.ndarray:
    """Motor output pulse width, µs, for rotor speeds n (rad/s), with the `[motor]` curve.

    The inverse of `rotor_speed_from_pwm`: PWM = pwm_min + u (pwm_max − pwm_min), u from
    `throttle_from_rotor_speed`.

    Parameters
    ----------
    n : ndarray, any shape
        Rotor speeds, rad/s.
    vehicle : VehicleConfig
        ``[motor]`` pwm_min, pwm_max, thrust_expo and ``[limits]`` rotor_speed_max.

    Returns
    -------
    ndarray, same shape
        PWM, µs, within [pwm_min, pwm_max].
    """
    motor = vehicle.motor
    u = throttle_from_rotor_speed(n, vehicle.limits.rotor_speed_max, motor.thrust_expo)
    return motor.pwm_min + u * (motor.pwm_max - motor.pwm_min)


def describe_curve(vehicle: VehicleConfig, pwm: bool) -> str:
    """The curve in words for a warning: its formula and the config values it used.

    Parameters
    ----------
    vehicle : VehicleConfig
        Its ``[motor]`` curve and ``rotor_speed_max``.
    pwm : bool
        The outputs are PWM (through the whole curve); else relative thrust commands.

    Returns
    -------
    str
    """
    motor, n_max = vehicle.motor, vehicle.limits.rotor_speed_max
    if pwm:
        return (f"n = {n_max:g} rad/s · sqrt((1 − e) u + e u²), e = [motor].thrust_expo = "
                f"{motor.thrust_expo:g}, u = (PWM − {motor.pwm_min:g}) / "
                f"({motor.pwm_max:g} − {motor.pwm_min:g}) µs")
    return f"n = {n_max:g} rad/s · sqrt(u), u the relative thrust command (0..1)"


def pwm_curve_caveat(vehicle: VehicleConfig) -> str:
    """What rotor speeds read from PWM outputs are, for a note: how and how far to trust them.

    Parameters
    ----------
    vehicle : VehicleConfig
        Its ``[motor]`` curve and ``rotor_speed_max``.

    Returns
    -------
    str
        "through the motor curve …: commanded, not measured, and only as right as the
        [motor] keys of the vehicle config".
    """
    return (f"through the motor curve {describe_curve(vehicle, pwm=True)}: commanded, not "
            "measured, and only as right as the [motor] keys of the vehicle config")


#: A battery that falls by more than this share while the motors run, with no ``[motor]
#: voltage`` to scale by, is said in a note.
VOLTAGE_SAG_NOTE = 0.03
#: Battery readings outside this range, V, are "unknown" markers (0, UINT16_MAX mV).
_VOLTAGE_RANGE = (1.0, 60.0)


def battery_scale(t: np.ndarray, battery: Series | None, vehicle: VehicleConfig,
                  where: str) -> tuple[np.ndarray | None, str | None]:
    """The factor V(t) / V_ref commanded rotor speeds take, and a note (module docstring).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times of the motor outputs, s, on the battery series' clock.
    battery : Series or None
        The battery voltage, V (one column), as logged.
    vehicle : VehicleConfig
        ``[motor] voltage``, V_ref (0: not stated).
    where : str
        The log and message, for the note.

    Returns
    -------
    scale : ndarray, shape (N,), or None
        Per output sample; None where nothing is scaled.
    note : str or None
        What was scaled, or how far the battery fell when nothing was.
    """
    if battery is None or not len(battery.t):
        return None, None
    volts = np.asarray(battery.values, float)[:, 0]
    ok = np.isfinite(volts) & (volts > _VOLTAGE_RANGE[0]) & (volts < _VOLTAGE_RANGE[1])
    if ok.sum() < 2:
        return None, None
    at = np.interp(t, battery.t[ok], volts[ok])
    low, high = float(np.min(at)), float(np.max(at))
    reference = vehicle.motor.voltage
    if reference > 0.0:
        return at / reference, (
            f"{where}: commanded rotor speeds scaled by the battery voltage "
            f"({low:.2f}–{high:.2f} V against [motor] voltage {reference:g} V)")
    if high > 0.0 and 1.0 - low / high > VOLTAGE_SAG_NOTE:
        return None, (
            f"{where}: the battery fell from {high:.2f} to {low:.2f} V in the log; commanded "
            f"rotor speeds do not see it ({100 * (1 - (low / high) ** 2):.0f} % of thrust "
            "at the same output): state [motor] voltage, the voltage the curve holds at, to "
            "scale them")
    return None, None


def commanded_rotor_speeds(log: str, outputs: Series, message: str, battery: Series | None,
                           battery_message: str, vehicle: VehicleConfig
                           ) -> tuple[Series, list[str]]:
    """Rotor speeds from logged PWM motor outputs: checked as PWM (`check_pwm_outputs`),
    through the vehicle's curve, scaled by the battery (`battery_scale`).

    Parameters
    ----------
    log : str
        The log, for messages.
    outputs : Series
        The motor outputs, µs, shape (N, k).
    message : str
        The log's message (or topic) of the outputs.
    battery : Series or None
        The battery voltage, V, on the outputs' clock.
    battery_message : str
        The log's message of the voltage.
    vehicle : VehicleConfig

    Returns
    -------
    speeds : Series
        rad/s, labelled as ``outputs``.
    notes : list of str
        What they are (`pwm_curve_caveat`) and what the battery did to them.
    """
    check_pwm_outputs(outputs.values, vehicle, f"{log}: {message}")
    speeds = Series(outputs.t, rotor_speed_from_pwm(outputs.values, vehicle), outputs.label)
    speeds, battery_notes = on_battery(speeds, battery, vehicle, f"{log}: {battery_message}")
    return speeds, [f"{log}: no ESC rpm; rotor speeds are motor outputs ({message}) "
                    f"{pwm_curve_caveat(vehicle)}", *battery_notes]


def on_battery(speeds: Series, battery: Series | None, vehicle: VehicleConfig, where: str
               ) -> tuple[Series, list[str]]:
    """Commanded rotor speeds times the battery's factor (`battery_scale`), and its note.

    Parameters
    ----------
    speeds : Series
        Rotor speeds through the curve, rad/s, shape (N, k).
    battery : Series or None
        The battery voltage, V, on the speeds' clock.
    vehicle : VehicleConfig
    where : str
        The log and the battery's message, for the note.

    Returns
    -------
    speeds : Series
        Scaled where ``[motor] voltage`` is stated and the log has the voltage.
    notes : list of str
        What was scaled, or how far the battery fell unscaled.
    """
    scale, note = battery_scale(speeds.t, battery, vehicle, where)
    if scale is not None:
        speeds = Series(speeds.t, speeds.values * scale[:, None], speeds.label)
    return speeds, [note] if note else []


#: The motor curve's rotor speeds may lie this share off a log's own ESC rpm (its median
#: ratio over the flight) before they are refused: c_T goes as the square of the error.
CURVE_RPM_TOLERANCE = 0.15


#: Share of the flight's high commanded speed (its 90th percentile, summed over rotors)
#: above which an ESC sample carries the vehicle and counts in the curve's scale.
CARRYING_SHARE = 0.5


@dataclass(frozen=True)
class CurveScale:
    """The motor curve's scale fitted to a log's own ESC rpm.

    Attributes
    ----------
    factor : float
        ESC rotor speed / the curve's, the median over the flight: the curve with
        ``rotor_speed_max × factor`` gives the ESC's speeds.
    sigma : float
        1σ of ``factor``: the ratios' robust spread over the square root of their
        effective number (their lag-1 correlation counted).
    samples : int
        ESC samples where both ran.
    """

    factor: float
    sigma: float
    samples: int


def fit_curve_scale(commanded: Series, esc: Series) -> CurveScale | None:
    """The scale that takes the curve's rotor speeds to the log's ESC rpm, however sparse.

    A log whose ESC rpm comes too seldom to follow a manoeuvre still says how fast the
    rotors turn on average: the ratio of the summed ESC speeds to the summed commanded ones
    at the ESC's times (a sum, so the two need not number the rotors alike), its median
    over the samples where both run and the rotors carry the vehicle (`CARRYING_SHARE`).

    Parameters
    ----------
    commanded : Series
        Rotor speeds through the motor curve, rad/s, shape (N, k).
    esc : Series
        The ESC's rotor speeds, rad/s, shape (M, k'), on the same clock.

    Returns
    -------
    CurveScale or None
        None with fewer than three samples where both run.
    """
    measured = np.nansum(np.asarray(esc.values, float), axis=1)
    curve = np.sum([np.interp(esc.t, commanded.t, column)
                    for column in np.asarray(commanded.values, float).T], axis=0)
    inside = (esc.t >= commanded.t[0]) & (esc.t <= commanded.t[-1])
    running = inside & (measured > 0.0) & (curve > 0.0)
    if running.sum() >= 3:
        # Idle and spin-up do not carry the vehicle (the curve's low end is an idle
        # setting, and the ESC lags a spin-up between its sparse samples).
        running &= curve >= CARRYING_SHARE * np.percentile(curve[running], 90)
    count = int(running.sum())
    if count < 3:
        return None
    ratio = measured[running] / curve[running]
    factor = float(np.median(ratio))
    deviation = ratio - factor
    spread = 1.4826 * float(np.median(np.abs(deviation)))
    rho = 0.0
    if count > 3 and np.std(deviation) > 0.0:
        rho = float(np.clip(np.corrcoef(deviation[:-1], deviation[1:])[0, 1], 0.0, 0.99))
    effective = max(count * (1.0 - rho) / (1.0 + rho), 1.0)
    # 1.2533: the median's σ over the mean's, for Gaussian ratios.
    return CurveScale(factor, 1.2533 * spread / np.sqrt(effective), count)


def check_curve_against_rpm(commanded: Series, esc: Series, where: str) -> CurveScale | None:
    """The curve's scale fitted to the log's ESC rpm (`fit_curve_scale`), refused beyond
    `CURVE_RPM_TOLERANCE`.

    Parameters
    ----------
    commanded, esc : Series
        As `fit_curve_scale` takes them.
    where : str
        The log and the messages, for the message.

    Returns
    -------
    CurveScale or None
        None where the two never run together.

    Raises
    ------
    LogFormatError
        The median ratio beyond the tolerance; one line with the ratio and what to fix.
    """
    fit = fit_curve_scale(commanded, esc)
    if fit is None or abs(fit.factor - 1.0) <= CURVE_RPM_TOLERANCE:
        return fit
    ratio = fit.factor
    raise LogFormatError(
        f"{where}: the motor curve's rotor speeds are {1.0 / ratio:.3g} × what the log's "
        f"own ESC rpm says (median over {fit.samples} ESC samples): the [motor] curve "
        "and rotor_speed_max do not describe these motors, and c_T from them would be "
        f"{ratio**2:.3g} × off; correct the curve (rotor_speed_max × {ratio:.3g}) or log "
        "the ESC rpm at 10 Hz or more")
