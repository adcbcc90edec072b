"""What runs while setpoints stream: the setpoint ticker, the flight guards, the progress line.

`SetpointStream` is the `MavlinkLink` ticker that sends SET_POSITION_TARGET_LOCAL_NED on a
drift-free `TickSchedule`, from whatever setpoint source the current phase of the flight
sets (a transfer move, a hold, the trajectory). Because the link fires it from every
wait, the stream never pauses while a command waits for its ACK.

`FlightGuards` watches each message from the vehicle and stops the flight the moment
something is wrong, by stopping the stream first and then raising:

- `ModeTaken`: the HEARTBEAT shows a mode other than the one mavsysid set (a pilot took
  over, or the autopilot's own failsafe: its STATUSTEXT of the last seconds is quoted) or
  the vehicle disarmed in flight; nothing more is sent, the pilot has control;
- `TrackingLost`: the vehicle is farther than the limit from the setpoint in effect.

Before that, a tracking error beyond half the limit is reported in one line when it
happens (again after it has come back under a quarter of the limit), and the motor
watch it carries (`mavsysid.flight.ground.motor_watch`) is switched off with the guards.
"""

from __future__ import annotations

import sys
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TextIO

from mavsysid.flight.autopilot_modes import mode_name
from mavsysid.flight.ground.mavlink_link import MavlinkLink
from mavsysid.flight.ground.setpoints import (
    Setpoint,
    SetpointLimits,
    TickSchedule,
    UnsafeSetpoint,
)
from mavsysid.flight.ground.telemetry_recorder import SetpointHistory, TelemetryRecorder

from mavsysid.errors import JobFailedError

if TYPE_CHECKING:
    from mavsysid.flight.ground.motor_watch import MotorWatch

__all__ = ["TRACKING_WARNING", "FlightGuards", "ModeTaken", "ProgressLine", "SetpointStream",
           "TrackingLost"]

SetpointSource = Callable[[float], Setpoint]

#: A STATUSTEXT this recent (streamer s) explains a mode change (a failsafe says why).
_REASON_AGE = 3.0

#: Share of the tracking-error limit from which a tracking error is reported.
TRACKING_WARNING = 0.5


class ModeTaken(JobFailedError):
    """Someone else changed the flight mode, or the vehicle disarmed, mid-flight.

    Parameters
    ----------
    change : str
        What changed ("the flight mode changed from GUIDED to LAND").
    texts : sequence of str
        The autopilot's STATUSTEXT around the change (a failsafe says why); none: maybe a
        pilot.
    """

    def __init__(self, change: str, texts: Sequence[str] = ()) -> None:
        self.change, self.texts = change, tuple(texts)
        why = ("the autopilot said: " + "; ".join(self.texts) if self.texts
               else "pilot takeover?")
        super().__init__(f"{change}, not by mavsysid ({why}): stopped streaming; the vehicle "
                         "is in the pilot's hands")


class TrackingLost(JobFailedError):
    """The tracking error exceeded its limit."""


class SetpointStream:
    """Sends setpoints from a source on a drift-free schedule (a `MavlinkLink` ticker).

    Parameters
    ----------
    link : MavlinkLink
    history : SetpointHistory
        Receives every setpoint sent, with its send time, for the pose log's references.
    rate : float
        Setpoints per streamer second, Hz.
    """

    def __init__(self, link: MavlinkLink, history: SetpointHistory, rate: float) -> None:
        self.link, self.history, self.period = link, history, 1.0 / rate
        self.schedule: TickSchedule | None = None
        self._source: SetpointSource | None = None
        self.last: Setpoint | None = None
        # The last line of defence: each setpoint is checked before it is sent.
        self.limits: SetpointLimits | None = None

    def start(self, source: SetpointSource) -> TickSchedule:
        """Stream ``source(t)``, t = s since now on the schedule (first tick now).

        Returns the phase's new schedule (its statistics are the phase's).
        """
        self._source = source
        self.schedule = TickSchedule(self.link.clock.now(), self.period)
        self.link.set_ticker(self)
        return self.schedule

    def stop(self) -> None:
        """Stop sending (at once: the link no longer fires this ticker)."""
        if self.link.ticker is self:
            self.link.set_ticker(None)
            self.history.add(self.link.clock.now(), None)
        self._source = None

    @property
    def streaming(self) -> bool:
        """Whether setpoints are being sent."""
        return self.link.ticker is self

    def next_deadline(self) -> float:
        """When the next setpoint is due, streamer s."""
        assert self.schedule is not None
        return self.schedule.deadline()

    def fire(self, now: float) -> None:
        """Send the setpoint of the tick due at ``now``."""
        assert self.schedule is not None and self._source is not None
        k = self.schedule.due(now)
        if k is None:
            return
        setpoint = self._source(k * self.period)
        if self.limits is not None and (why := self.limits.refusal(setpoint)) is not None:
            self.stop()
            raise UnsafeSetpoint(why)
        fields = setpoint.message_fields()
        v = self.link.vehicle
        self.link.send(self.link.mav.set_position_target_local_ned_encode(
            int(now * 1000) & 0xFFFFFFFF, v.system, v.component, fields["coordinate_frame"],
            fields["type_mask"], fields["x"], fields["y"], fields["z"], fields["vx"],
            fields["vy"], fields["vz"], fields["afx"], fields["afy"], fields["afz"],
            fields["yaw"], fields["yaw_rate"]))
        self.history.add(now, setpoint, self.schedule.start + k * self.period)
        self.last = setpoint


class FlightGuards:
    """Stops the flight on a foreign mode change, a disarm, or lost tracking.

    Add `on_message` as a link listener after the recorder's (it reads the recorder's
    latest row). Guards are off until armed: set `expected_mode` (custom_mode) once the
    mode mavsysid set is confirmed, `expect_armed` once armed, `max_tracking_error` (m)
    while setpoints with feed-forward are flown. `say` receives the tracking reports,
    `motors` is the flight's motor watch (switched off by `disable`).
    """

    def __init__(self, link: MavlinkLink, stream: SetpointStream,
                 recorder: TelemetryRecorder) -> None:
        self.link, self.stream, self.recorder = link, stream, recorder
        self.expected_mode: int | None = None
        self.expect_armed = False
        self.max_tracking_error: float | None = None
        self.say: Callable[[str], None] = lambda _text: None
        self.motors: MotorWatch | None = None
        self._tracking_reported = False
        self._texts: deque[tuple[float, str]] = deque(maxlen=8)

    def disable(self) -> None:
        """Turn every guard off (before mavsysid changes the mode itself)."""
        self.expected_mode, self.expect_armed, self.max_tracking_error = None, False, None
        if self.motors is not None:
            self.motors.active = False

    def _report_tracking(self, error: float, limit: float, t: float) -> None:
        """One line when the error first passes `TRACKING_WARNING` of the limit."""
        if error < 0.5 * TRACKING_WARNING * limit:
            self._tracking_reported = False
        elif error >= TRACKING_WARNING * limit and not self._tracking_reported:
            self._tracking_reported = True
            self.say(f"warning: tracking error {error:.2f} m at t = {t:.2f} s, past "
                     f"{100 * TRACKING_WARNING:.0f} % of the {limit:g} m limit "
                     "(--max-tracking-error)")

    def on_message(self, msg: Any, t: float) -> None:
        """Check one message from the vehicle (a link listener)."""
        kind = msg.get_type()
        v = self.link.vehicle
        if kind == "STATUSTEXT":
            self._texts.append((t, str(msg.text).strip()))
        elif kind == "HEARTBEAT" and v.autopilot is not None:
            recent = [text for when, text in self._texts if t - when <= _REASON_AGE]
            if self.expected_mode is not None and v.custom_mode != self.expected_mode:
                expected = mode_name(v.autopilot, self.expected_mode)
                self.stream.stop()
                self.disable()
                raise ModeTaken(f"the flight mode changed from {expected} to {v.mode}", recent)
            if self.expect_armed and not v.armed:
                self.stream.stop()
                self.disable()
                raise ModeTaken(f"the vehicle disarmed in flight (mode {v.mode})", recent)
        elif kind == "LOCAL_POSITION_NED" and self.max_tracking_error is not None:
            latest = self.recorder.latest
            error = None if latest is None else latest.tracking_error
            if error is not None and latest is not None:
                self._report_tracking(error, self.max_tracking_error, latest.t)
            if error is not None and error > self.max_tracking_error:
                self.stream.stop()
                limit = self.max_tracking_error
                self.max_tracking_error = None
                raise TrackingLost(f"tracking error {error:.2f} m exceeds the limit "
                                   f"{limit:g} m at t = {latest.t:.2f} s")


class ProgressLine:
    """The live line on stderr: trajectory time, setpoint rate, tracking error.

    On a terminal the line is redrawn in place a few times a second; otherwise (a log
    file, a pipe) a full line is printed every ``every`` seconds of trajectory time.
    """

    def __init__(self, duration: float, stream: TextIO | None = None, every: float = 5.0,
                 enabled: bool = True) -> None:
        self.duration, self.every, self.enabled = duration, every, enabled
        self.out = stream or sys.stderr
        self.tty = bool(getattr(self.out, "isatty", lambda: False)())
        self._next = 0.0
        self._drawn = False

    def update(self, t: float, rate: float, error: float | None, wall_now: float) -> None:
        """Show trajectory time ``t`` (s), setpoint ``rate`` (Hz), tracking ``error`` (m)."""
        if not self.enabled:
            return
        due = wall_now if self.tty else t
        if due < self._next:
            return
        self._next = due + (0.25 if self.tty else self.every)
        err = "  —  " if error is None else f"{100.0 * error:5.1f}"
        text = (f"  t {t:6.1f} / {self.duration:.1f} s   setpoints {rate:5.1f} Hz   "
                f"tracking error {err} cm")
        if self.tty:
            self.out.write("\r" + text)
            self._drawn = True
        else:
            self.out.write(text + "\n")
        self.out.flush()

    def close(self) -> None:
        """End the in-place line."""
        if self._drawn:
            self.out.write("\n")
            self.out.flush()
            self._drawn = False
