"""Flying a trajectory file over MAVLink: the whole sequence of ``mavsysid stream``.

1. Check the plan (vehicle name, every 100 Hz sample inside the box), create the flight
   directory, connect, wait for the vehicle's heartbeat and tell ArduPilot from PX4.
2. Ask for LOCAL_POSITION_NED, ATTITUDE_QUATERNION and ESC rpm at the telemetry rate
   and for the IMU at the rate the link carries (SET_MESSAGE_INTERVAL,
   `mavsysid.flight.ground.imu_telemetry`), wait for a usable local position, measure the
   rates achieved (the pose log carries the IMU if it came), and check the vehicle
   (airframe, health, rates): refuse, or warn. With the log download on, ArduPilot logs
   its IMU at the loop rate for the flight (LOG_BITMASK IMU_FAST, restored after).
3. ArduPilot: GUIDED, arm, NAV_TAKEOFF to the start altitude. PX4: stream a hold
   setpoint, then OFFBOARD, arm, and climb with setpoints.
4. Fly to the trajectory's start with a smooth move and settle there; stream the
   trajectory (position, velocity, acceleration, yaw, yaw rate) at the setpoint rate on
   a drift-free clock; hold at the end; LAND (or keep hovering with ``land=False``).

Failures stop the stream first and then act safely (see `mavsysid.flight.ground.stream_control`): a
lost
heartbeat leaves the vehicle to its own failsafe; a foreign mode change leaves it to the
pilot; lost tracking switches to BRAKE (PX4: HOLD); an interrupt (Ctrl-C, SIGTERM)
brakes, then lands. Everything is recorded as it arrives (`mavsysid.flight.ground.stream_session`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.autopilot_limits import check_session_limits
from mavsysid.flight.ground.continuation import (
    Continuation,
    ContinuationStopped,
    SegmentRun,
    continue_flight,
    stream_segment,
)
from mavsysid.flight.ground.flight_safety import (
    before_arming,
    install_safety,
    restore_parameters,
)
from mavsysid.flight.ground.frame_check import (
    check_frame,
    frame_parameter_names,
    px4_rotor_parameter_names,
)
from mavsysid.flight.ground.imu_telemetry import request_imu
from mavsysid.flight.ground.landing import LandingLimits, wait_disarmed
from mavsysid.flight.ground.log_download import log_imu_fast
from mavsysid.flight.ground.mavlink_link import HeartbeatLost
from mavsysid.flight.ground.motor_watch import MotorLimits, MotorWatch
from mavsysid.flight.ground.preflight import PreflightReport, check_vehicle
from mavsysid.flight.ground.rotor_watch import RotorWatch
from mavsysid.flight.ground.setpoints import SmoothMove, hold, trajectory_setpoint
from mavsysid.flight.ground.stream_control import ModeTaken
from mavsysid.flight.ground.stream_session import StreamSession, StreamSettings
from mavsysid.flight.ground.vehicle_contact import meet_vehicle

from mavsysid.errors import JobFailedError

__all__ = ["fly"]

_TELEMETRY = ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "ESC_TELEMETRY_1_TO_4")
#: SYS_STATUS rate while preparing, Hz: the pre-arm wait sees each change of health.
_HEALTH_RATE = 2.0


def fly(session: StreamSession, say: Callable[[str], None], progress: bool = True,
        at_end: Callable[[StreamSession], None] | None = None,
        continuation: Continuation | None = None) -> None:
    """Fly the session's trajectory (steps 1–4 of the module docstring, after the plan check).

    Parameters
    ----------
    session : StreamSession
        Opened (`mavsysid.flight.ground.stream_session.open_session`), plan already checked.
    say : callable
        Receives one-line progress messages.
    progress : bool
        Show the live progress line while the trajectory streams.
    at_end : callable, optional
        Called with the session while the vehicle hovers at the trajectory's end, before
        landing (a benchmark's own experiment, say); it may stream other setpoints through
        ``session.stream`` and should leave a hold streaming.
    continuation : callable, optional
        Asked for further trajectories after the first, flown in the same run while the
        vehicle holds in between (`mavsysid.flight.ground.continuation`); a refusal lands.

    Raises
    ------
    JobFailedError
        Refused or aborted, after the safe action (the session records why).
    KeyboardInterrupt
        After braking and landing.
    """
    _Flight(session, say, progress, at_end, continuation).run()


class _Flight:
    def __init__(self, s: StreamSession, say: Callable[[str], None], progress: bool,
                 at_end: Callable[[StreamSession], None] | None,
                 continuation: Continuation | None) -> None:
        self.s, self.say, self.progress, self.at_end = s, say, progress, at_end
        self.continuation = continuation
        self.first: SegmentRun | None = None  # how the session's trajectory streamed
        self.settings: StreamSettings = s.settings
        self.link, self.commands, self.stream, self.guards = s.link, s.commands, s.stream, s.guards
        self.recorder = s.recorder
        self.link.add_listener(RotorWatch(self.link.vehicle, say).on_message)
        self.motors = MotorWatch(s.config, say,
                                 MotorLimits(imbalance_abort=self.settings.max_motor_imbalance))
        self.link.add_listener(self.motors.on_message)
        self.guards.motors, self.guards.say = self.motors, say
        self.home_up: float | None = None  # take-off height, m ENU (the landing's ground)

    def run(self) -> None:
        try:
            self._connect()
            self._prepare()
            if self.settings.dry_run:
                self._dry_run_end()
                return
            self._take_off()
            self._to_start()
            self._trajectory()
            self._finish()
        except KeyboardInterrupt:
            self.stream.stop()
            self._interrupted()
            raise
        except JobFailedError as error:
            self.stream.stop()
            if isinstance(error, ModeTaken):
                error = self._explained(error)
            self.s.note_failure(str(error))
            # A lost link or a pilot in control: hands off. Anything else in the air: hold.
            # A stopped continuation has landed already: no BRAKE in the middle of a landing.
            if not isinstance(error, HeartbeatLost | ModeTaken | ContinuationStopped) and \
                    self.link.vehicle.armed:
                self._hold_after_abort()
            raise error
        finally:
            self.s.note("motor_watch", {
                "findings": self.motors.findings,
                "peak_imbalance": round(self.motors.peak_imbalance, 3),
                "off": self.motors.off_reason})
            restore_parameters(self.s, self.say)

    def _explained(self, taken: ModeTaken) -> ModeTaken:
        """``taken`` with what the autopilot says in the next second: a failsafe announces
        itself just after the heartbeat that shows its mode (ArduCopter: "EKF Failsafe:
        changed to LAND Mode"). Only listens; nothing is sent."""
        texts = list(taken.texts)

        def listen(msg: Any, _t: float) -> None:
            if msg.get_type() == "STATUSTEXT":
                texts.append(str(msg.text).strip())

        self.link.add_listener(listen)
        try:
            self.link.poll(1.0)
        except JobFailedError:
            pass  # a lost link: what was said so far
        finally:
            self.link.remove_listener(listen)
        if texts == list(taken.texts):
            return taken
        return ModeTaken(taken.change, texts)

    # --- steps ---------------------------------------------------------------------------

    def _connect(self) -> None:
        v = meet_vehicle(self.link, self.settings.heartbeat_timeout, "flight refused",
                         self.say, watch=True)
        self.s.note_vehicle()
        self.say(f"connected: {v.autopilot.name.lower()} {self.s.type_name}, system "
                 f"{v.system}, mode {v.mode}, {'armed' if v.armed else 'disarmed'}")

    def _prepare(self) -> None:
        rate = self.settings.telemetry_rate
        names = list(_TELEMETRY)
        if self.s.config.rotor_count > 4:
            names.append("ESC_TELEMETRY_5_TO_8")
        for name in names:
            if (why := self.commands.set_message_interval(name, rate)) is not None:
                self.say(f"warning: the vehicle did not accept {name} at {rate:g} Hz: {why}")
        # Motor outputs for the log, a fallback for missing ESC rpm; a refusal is no matter.
        self.commands.set_message_interval("SERVO_OUTPUT_RAW", rate)
        imu, imu_rate, refused = request_imu(self.commands.set_message_interval,
                                             self.link.vehicle.autopilot, self.link.connect)
        # Health as it changes: the pre-arm wait judges the latest SYS_STATUS, and a vehicle
        # that sends none unasked (ArduPilot on a fresh link) would leave it judging one
        # stale reply for the whole wait.
        self.commands.set_message_interval("SYS_STATUS", _HEALTH_RATE)
        self.commands.wait_position(self.settings.position_timeout)
        achieved = self._measure_rates(2.0)
        shown = ", ".join(f"{n} {achieved.get(n, 0.0):.1f} Hz" for n in names)
        self.say(f"telemetry (asked {rate:g} Hz): {shown}; {imu} {achieved.get(imu, 0.0):.1f} "
                 f"Hz (asked {imu_rate:g} Hz{f', refused: {refused}' if refused else ''})")
        self.s.note_rates(achieved)
        self.recorder.use_imu(achieved.get(imu, 0.0) > 0.0)
        self.s.note("imu", {"message": imu, "requested_hz": imu_rate, "refused": refused,
                            "preflight_hz": achieved.get(imu, 0.0),
                            "in_pose_csv": bool(self.recorder.writes_imu)})
        if self.s.last_sys_status is None:
            self.commands.request_message("SYS_STATUS")
            self.link.poll(1.0)
        self.s.prearm.wait_ready(self.settings.prearm_timeout, self.say)
        report = check_vehicle(self.s.config, self.link.vehicle, self.s.type_name,
                               self.s.last_sys_status, self.s.sensor_names, achieved, rate,
                               self._pose().position, self.s.box) + self._frame_report()
        for warning in report.warnings:
            self.say(f"warning: {warning}")
        report.raise_if_refused()
        check_session_limits(self.s, self.say)  # before anything is changed
        if self.settings.download_log and self.link.vehicle.autopilot is Autopilot.ARDUPILOT:
            log_imu_fast(self.s.parameters, self.say)  # recorded with the fence's changes
        install_safety(self.s, self._pose().position, self.say)
        self.say(before_arming(self.s, self._pose().position))
        self.link.watch_silence = True  # telemetry streams: a second of silence is a loss

    def _frame_report(self) -> PreflightReport:
        """The autopilot's frame parameters against the vehicle file (`check_frame`);
        what it reported goes into meta.json (``autopilot.frame_parameters``)."""
        autopilot = self.link.vehicle.autopilot
        assert autopilot is not None
        values = self.s.parameters.read(list(frame_parameter_names(autopilot)), timeout=3.0)
        count = int(values.get("CA_ROTOR_COUNT", 0))
        if count > 0:
            values.update(self.s.parameters.read(list(px4_rotor_parameter_names(count)),
                                                 timeout=5.0))
        self.s.meta["autopilot"]["frame_parameters"] = dict(values)
        return check_frame(self.s.config, autopilot, values)

    def _dry_run_end(self) -> None:
        """Every check passed: list what the flight would change, arm nothing."""
        planned = self.s.parameters.planned
        self.s.note("dry_run_parameters", {n: {"now": a, "flight": b}
                                           for n, (a, b) in planned.items()})
        self.say("dry run: would set " + (", ".join(f"{n} {a:g} → {b:g}" for n, (a, b) in
                                                    planned.items()) or "no parameter"))
        self.say("dry run: every check passed; nothing armed, no parameter changed")
        self.s.note_complete()

    def _measure_rates(self, seconds: float) -> dict[str, float]:
        before, t0 = dict(self.recorder.counts), self.link.clock.now()
        self.link.poll(seconds)
        elapsed = self.link.clock.now() - t0
        return {k: (n - before.get(k, 0)) / elapsed for k, n in self.recorder.counts.items()
                if n > before.get(k, 0)}

    def _set_mode(self, name: str) -> None:
        self.guards.expected_mode = None
        self.commands.set_mode(name)
        self.guards.expected_mode = self.link.vehicle.custom_mode
        self.say(f"mode {name}")

    def _pose(self) -> Any:
        latest = self.recorder.latest
        if latest is None:
            raise JobFailedError("no pose from the vehicle (LOCAL_POSITION_NED with attitude)")
        return latest

    def _take_off(self) -> None:
        start_z = self.s.trajectory.flat_outputs(np.array([0.0])).position[0, 2]
        ground = self._pose()
        self.home_up = float(ground.position[2])
        if self.link.vehicle.autopilot is Autopilot.ARDUPILOT:
            self._set_mode("GUIDED")
            self.commands.arm(explain=self.s.prearm.reason)
            self.guards.expect_armed = True
            self.say("armed")
            altitude = max(0.3, float(start_z - ground.position[2]))
            self.commands.takeoff(altitude)
            self.say(f"taking off to {altitude:.2f} m")
            self._wait_altitude(ground.position[2] + altitude)
            self.motors.active = True
        else:
            here = hold(ground.position, ground.yaw)
            self.stream.start(lambda _t: here)
            self.link.poll(1.5)  # PX4 wants setpoints for > 1 s before OFFBOARD
            self._set_mode("OFFBOARD")
            self.commands.arm(explain=self.s.prearm.reason)
            self.guards.expect_armed = True
            self.say("armed")
            top = np.array([*ground.position[:2], max(start_z, ground.position[2] + 0.3)])
            self._move(ground.position, ground.yaw, top, ground.yaw, "climbing")
            self.motors.active = True

    def _wait_altitude(self, z: float) -> None:
        timeout = 15.0 + 2.0 * abs(z)
        deadline = self.link.clock.now() + timeout
        while self._pose().position[2] < z - 0.1:
            if self.link.clock.now() > deadline:
                raise JobFailedError(f"take-off did not reach {z:.2f} m within {timeout:g} s "
                                     f"(at {self._pose().position[2]:.2f} m)")
            self.link.poll(0.05)

    def _move(self, p0: np.ndarray, yaw0: float, p1: np.ndarray, yaw1: float,
              what: str) -> None:
        move = SmoothMove.between(p0, yaw0, p1, yaw1, self.settings.transfer_speed)
        self.say(f"{what}: {np.linalg.norm(np.asarray(p1) - p0):.2f} m in "
                 f"{move.duration:.1f} s")
        self.guards.max_tracking_error = self.settings.max_tracking_error
        self.stream.start(move.setpoint)
        self.link.poll(move.duration)

    def _to_start(self) -> None:
        traj = self.s.trajectory
        first = trajectory_setpoint(traj, 0.0)
        start = hold(np.array(first.position), first.yaw)
        pose = self._pose()
        self._move(pose.position, pose.yaw, np.array(start.position), start.yaw,
                   "flying to the trajectory's start")
        self.stream.start(lambda _t: start)
        st = self.settings
        clock = self.link.clock
        began = clock.now()
        calm_since: float | None = None
        while True:
            self.link.poll(0.05)
            p = self._pose()
            now = clock.now()
            calm = (p.tracking_error is not None and p.tracking_error < st.settle_tolerance
                    and float(np.linalg.norm(p.velocity)) < 0.1)
            calm_since = (calm_since or now) if calm else None
            if calm_since is not None and now - calm_since >= st.settle_time:
                self.say(f"settled at the start in {now - began:.1f} s")
                return
            if now - began > st.settle_timeout:
                self.say(f"warning: not settled within {st.settle_timeout:g} s (error "
                         f"{p.tracking_error or 0.0:.3f} m); starting anyway")
                return

    def _trajectory(self) -> None:
        self.first = stream_segment(self.s, self.s.trajectory, self.progress, self.say,
                                    self.s.note_trajectory_start)
        self.s.note_trajectory_end(self.first.end, self.first.statistics)

    def _finish(self) -> None:
        last = trajectory_setpoint(self.s.trajectory, self.s.trajectory.duration)
        end = hold(np.array(last.position), last.yaw)
        self.stream.start(lambda _t: end)
        self.link.poll(self.settings.hold_time)
        if self.continuation is not None and self.first is not None:
            try:
                continue_flight(self.s, end, self.first, self.continuation, self._move,
                                self.progress, self.say)
            except ContinuationStopped as error:
                self.say(str(error))
                self._land()  # then the flight fails with that reason
                raise
        if self.at_end is not None:
            self.at_end(self.s)
        self.guards.max_tracking_error = None
        self.motors.active = False
        autopilot = self.link.vehicle.autopilot
        if not self.settings.land:
            if autopilot is Autopilot.PX4:
                self.stream.stop()
                self._set_mode("HOLD")  # OFFBOARD without setpoints would fail safe
            else:
                self.stream.stop()  # GUIDED holds the last position target
            self.say("hovering at the trajectory's end (--no-land)")
            self.s.note_complete()
            return
        self._land()
        self.s.note_complete()

    def _land(self) -> None:
        """Stop streaming, LAND, wait for the disarm (see `_wait_landed`)."""
        self.guards.max_tracking_error = None
        self.motors.active = False
        self.stream.stop()
        self.guards.expect_armed = False
        self._set_mode("LAND")
        self.say("landing")
        self._wait_landed()

    def _wait_landed(self) -> bool:
        """Wait until the vehicle has landed and is disarmed: True. False when the operator
        took over (another mode than the one we set) or the landing stalled
        (`mavsysid.flight.ground.landing.wait_disarmed`, one line each). A second Ctrl-C
        ends the wait at once (`StreamSession`)."""
        limits = LandingLimits(stall=self.settings.land_timeout)
        return wait_disarmed(self.link, self.commands, self.say, self.home_up, limits)

    # --- failures --------------------------------------------------------------------------

    def _safe_mode(self) -> str:
        return "BRAKE" if self.link.vehicle.autopilot is Autopilot.ARDUPILOT else "HOLD"

    def _hold_after_abort(self) -> None:
        """Lost tracking: let the autopilot stop in BRAKE / HOLD, then land."""
        self.guards.disable()
        self._stop_then_land(f"aborted to {self._safe_mode()}: the vehicle holds its "
                             "position", "aborted")

    def _interrupted(self) -> None:
        """Ctrl-C: brake (PX4: hold), then land; skipped if never armed."""
        self.guards.disable()
        self.s.note_failure("interrupted (SIGINT/SIGTERM): braked, then landed")
        if not self.link.vehicle.armed:
            self.say("interrupted; the vehicle is not armed, nothing to do")
            return
        self._stop_then_land(None, "interrupted")

    def _stop_then_land(self, held: str | None, why: str) -> None:
        """BRAKE (PX4: HOLD) until stopped, LAND, and wait until it has landed or the
        operator takes over, so that the parameters are restored on the ground."""
        try:
            self._brake_land_wait(held, why)
        except JobFailedError as error:  # a lost link while landing: report, keep the first
            self.say(f"warning: {error}")

    def _brake_land_wait(self, held: str | None, why: str) -> None:
        mode = self._safe_mode()
        modes = self.link.vehicle.autopilot.modes  # type: ignore[union-attr]
        for step in (mode, "LAND"):
            try:
                self.commands.set_mode(step)
            except JobFailedError as error:
                self.say(f"warning: could not switch to {step}: {error}")
                continue
            self.say(held if step == mode and held is not None else f"{why}: mode {step}")
            if step == mode:
                self._wait_stopped(3.0)
                if self.link.vehicle.custom_mode != modes[mode]:
                    self.say(f"the operator took over (mode {self.link.vehicle.mode}); not "
                             "landing")
                    return
        self._wait_landed()

    def _wait_stopped(self, seconds: float) -> None:
        deadline = self.link.clock.now() + seconds
        while self.link.clock.now() < deadline:
            self.link.poll(0.05)
            latest = self.recorder.latest
            if latest is not None and float(np.linalg.norm(latest.velocity)) < 0.2:
                return
