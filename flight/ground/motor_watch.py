"""Motor faults seen in flight: the motor outputs against each other, and against their top.

The autopilot's controller hides a weak motor: its integrators raise that motor's command
until the vehicle flies level again, and the tracking stays fair until the motor runs out
of range. The motor outputs (SERVO_OUTPUT_RAW, µs) show it plainly: with motor 1 of
ArduCopter SITL at 70 % thrust the autopilot commands about 1807 µs on it against 1559 µs
on its mirror. `MotorWatch` reads each output through the vehicle file's ``[motor]``
curve as the thrust it asks for, relative to full thrust, f = (1 − e) u + e u² with u the
output's share of [pwm_min, pwm_max], and watches, while the vehicle flies mavsysid's
setpoints:

- **imbalance**: over the last `MotorLimits.window` seconds, the mean f of each motor
  against that of its mirror, the rotor opposite it through the centre
  (`mavsysid.vehicle.motor_order.mirror_rotors`), which carries the same share in
  trimmed flight. A ratio R means the motor is asked for R times its mirror's thrust: a
  weak motor or propeller (one making 1/R of what its command asks, as the mixer's
  integrators settle), or the centre of gravity off towards it. Mirrors that spin the same
  way (a quad X) share the yaw command; mirrors that spin opposite ways (a hexa, an octo)
  do not, and a yaw manoeuvre alone loads them 1.6 : 1 over seconds on the simulated
  Firefly. A weak motor's share is steady, a manoeuvre's comes and goes: for those pairs
  the yaw share of the outputs (their projection on the spin directions) is taken out as
  far as it departs from its mean over `MotorLimits.steady_window`, and they are judged
  once that much has flown. Reported from `MotorLimits.imbalance_warning`, aborted from
  `MotorLimits.imbalance_abort`;
- **saturation**: an output at the top of its range (u ≥ `MotorLimits.saturated`) for
  `MotorLimits.saturation_warning` s in a row is reported, for
  `MotorLimits.saturation_abort` s aborted (the autopilot has lost authority; ArduCopter's
  own thrust-loss check waits 1 s of a motor at full output).

Each finding is one line when it happens; an abort raises `MotorFault` from the link's
listener, so the flight stops streaming, holds and lands (`mavsysid.flight.ground.streamer`).
Outputs outside the vehicle file's PWM range (DShot, DroneCAN commands) are not PWM: the
watch says so once and stays off. Without SERVO_OUTPUT_RAW there is nothing to watch.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsysid.formats.motor_curve import throttle_from_pwm
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.motor_order import mirror_rotors, output_order

from mavsysid.errors import JobFailedError

__all__ = ["MotorFault", "MotorLimits", "MotorWatch"]

#: PWM beyond the vehicle file's range by more than this, µs, is not a PWM output.
_PWM_SLACK = 50.0


class MotorFault(JobFailedError):
    """A motor worked far harder than its mirror, or sat at its top, past the limit."""


@dataclass(frozen=True)
class MotorLimits:
    """When `MotorWatch` reports and when it aborts.

    Attributes
    ----------
    imbalance_warning, imbalance_abort : float
        Thrust asked of a motor over that of its mirror (mean over `window`), ratio > 1.
    window : float
        Averaging window of the imbalance, streamer s (long enough that manoeuvres,
        which load opposite rotors unevenly for a moment, average out).
    steady_window : float
        The yaw share's steady part is its mean over this long, streamer s.
    saturated : float
        Share of the output range at which a motor counts as saturated.
    saturation_warning, saturation_abort : float
        Streamer seconds in a row a motor may stay saturated before a report / an abort.
    """

    imbalance_warning: float = 1.25
    imbalance_abort: float = 2.0
    window: float = 2.0
    steady_window: float = 10.0
    saturated: float = 0.98
    saturation_warning: float = 0.25
    saturation_abort: float = 1.0


class MotorWatch:
    """Watches the motor outputs for a weak motor and for saturation (module docstring).

    Parameters
    ----------
    config : VehicleConfig
        The vehicle: rotor positions (mirrors), ``[autopilot] frame`` (output order),
        ``[motor]`` curve.
    say : callable
        Receives the one-line reports.
    limits : MotorLimits, optional

    Attributes
    ----------
    active : bool
        Whether the flight is on mavsysid's setpoints (airborne); off, nothing is judged.
    findings : list of dict
        What was reported, for meta.json: kind, motor, value, streamer time.
    peak_imbalance : float
        Largest windowed imbalance seen while active (1 before any).

    Use `on_message` as a link listener.
    """

    def __init__(self, config: VehicleConfig, say: Callable[[str], None],
                 limits: MotorLimits | None = None) -> None:
        self.say, self.limits = say, limits or MotorLimits()
        self._e = config.motor.thrust_expo
        self._pwm = (config.motor.pwm_min, config.motor.pwm_max)
        order = output_order(config.rotor_positions, config.rotor_directions,
                             config.autopilot_frame)
        rotor_mirror = mirror_rotors(config.rotor_positions)
        output_of = {rotor: i for i, rotor in enumerate(order)}
        #: Motor output index → its mirror's output index (None: no mirror).
        self.mirrors = tuple(None if rotor_mirror[r] is None else output_of[rotor_mirror[r]]
                             for r in order)
        self._k = len(order)
        self._spins = np.asarray(config.rotor_directions, dtype=float)[list(order)]
        self.active = False
        self.off_reason: str | None = None
        self.findings: list[dict[str, Any]] = []
        self.peak_imbalance = 1.0
        self._samples: deque[tuple[float, np.ndarray]] = deque()
        self._yaw: deque[tuple[float, float]] = deque()  # the yaw share, steady window
        self._saturated_since: list[float | None] = [None] * self._k
        self._warned: set[tuple[str, int]] = set()

    def on_message(self, msg: Any, t: float) -> None:
        """Judge one SERVO_OUTPUT_RAW (a link listener); raises `MotorFault` past a limit.

        Parameters
        ----------
        msg : MAVLink message
            Any message from the vehicle; only SERVO_OUTPUT_RAW port 0 is read.
        t : float
            Streamer time of receipt, s.
        """
        if msg.get_type() != "SERVO_OUTPUT_RAW" or getattr(msg, "port", 0) != 0:
            return
        if self.off_reason is not None:
            return
        raw = np.array([getattr(msg, f"servo{i + 1}_raw", 0) or 0 for i in range(self._k)],
                       dtype=float)
        if not self.active:
            self._samples.clear()
            self._yaw.clear()
            self._saturated_since = [None] * self._k
            return
        if not self._pwm_outputs(raw):
            return
        u = throttle_from_pwm(raw, *self._pwm)
        f = (1.0 - self._e) * u + self._e * u * u
        self._samples.append((t, f))
        self._yaw.append((t, float(f @ self._spins) / self._k))
        while self._samples and self._samples[0][0] < t - self.limits.window:
            self._samples.popleft()
        while self._yaw and self._yaw[0][0] < t - self.limits.steady_window:
            self._yaw.popleft()
        self._saturation(u, t)
        self._imbalance(t)

    def _pwm_outputs(self, raw: np.ndarray) -> bool:
        lo, hi = self._pwm
        if np.all((raw >= lo - _PWM_SLACK) & (raw <= hi + _PWM_SLACK)):
            return True
        self.off_reason = (f"motor outputs {raw.min():g}..{raw.max():g} are not in the vehicle "
                           f"file's PWM range [{lo:g}, {hi:g}] µs")
        self.say(f"warning: {self.off_reason}: the motor watch is off for this flight (set "
                 "[motor] pwm_min/pwm_max to the autopilot's output range)")
        return False

    def _report(self, kind: str, motor: int, text: str, value: float, t: float) -> None:
        if (kind, motor) in self._warned:
            return
        self._warned.add((kind, motor))
        self.findings.append({"kind": kind, "motor_output": motor + 1, "value": round(value, 3),
                              "streamer_time_s": round(t, 3)})
        self.say(f"warning: {text}")

    def _abort(self, kind: str, motor: int, text: str, value: float, t: float) -> None:
        self.active = False
        self.findings.append({"kind": kind, "motor_output": motor + 1, "value": round(value, 3),
                              "streamer_time_s": round(t, 3), "aborted": True})
        raise MotorFault(text)

    def _saturation(self, u: np.ndarray, t: float) -> None:
        lim = self.limits
        for i, share in enumerate(u):
            if share < lim.saturated:
                self._saturated_since[i] = None
                continue
            since = self._saturated_since[i]
            if since is None:
                self._saturated_since[i] = since = t
            held = t - since
            if held >= lim.saturation_abort:
                self._abort("saturation", i, f"motor {i + 1} at the top of its range for "
                            f"{held:.1f} s (limit {lim.saturation_abort:g} s): the autopilot has "
                            "no authority left; aborted", held, t)
            if held >= lim.saturation_warning:
                self._report("saturation", i, f"motor {i + 1} at the top of its range for "
                             f"{held:.2f} s", held, t)

    def _imbalance(self, t: float) -> None:
        lim = self.limits
        if not self._samples or t - self._samples[0][0] < 0.9 * lim.window:
            return
        f = np.array([f for _, f in self._samples])
        mean = f.mean(axis=0)
        # The yaw share's departure from its steady mean: a manoeuvre's, not a weak motor's.
        yaw = float(np.mean(f @ self._spins)) / self._k - float(np.mean([y for _, y in self._yaw]))
        steady = t - self._yaw[0][0] >= 0.9 * lim.steady_window
        for i, j in enumerate(self.mirrors):
            if j is None:
                continue
            mine, theirs = mean[i], mean[j]
            if self._spins[i] != self._spins[j]:
                if not steady:
                    continue
                mine, theirs = mine - self._spins[i] * yaw, theirs - self._spins[j] * yaw
            if theirs <= 0.02:
                continue
            ratio = float(mine / theirs)
            self.peak_imbalance = max(self.peak_imbalance, ratio)
            what = (f"motor {i + 1} is asked for {ratio:.2f}× the thrust of motor {j + 1}, its "
                    f"mirror, over {lim.window:g} s: a weak motor or propeller, or the centre "
                    "of gravity off towards it")
            if ratio >= lim.imbalance_abort:
                self._abort("imbalance", i, f"{what}; beyond {lim.imbalance_abort:g}×, "
                            "aborted", ratio, t)
            if ratio >= lim.imbalance_warning:
                self._report("imbalance", i, what, ratio, t)
