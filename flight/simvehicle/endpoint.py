"""The simulated MAVLink vehicle: one loop that ties link, autopilot, physics and telemetry.

One thread does everything, in sim-time ticks of 2 ms paced by `mavsysid.flight.simvehicle.clock`:
drain the link without blocking and act on what came (commands → COMMAND_ACK,
setpoints, parameters, stream requests, log downloads), run the autopilot's timeouts and
failsafes, send the telemetry that is due, record the tick in the vehicle's own flight
log (`mavsysid.flight.simvehicle.onboard_log`, served over the log protocol), and advance
the physics by one tick. Falling behind
runs ticks back to back until caught up, so sim time stays wall time × speedup. With
``lockstep`` the loop also sends lock-step frames and reads the link only while a frame
waits for the ground station's acknowledgement, into an inbox that the tick after the
acknowledgement handles: what the ground station sends between two acknowledgements takes
effect at the same tick on an idle or a busy machine, whenever it was sent (see
`mavsysid.flight.simvehicle.clock`).

With a signing key, everything sent is signed, and unsigned or wrongly signed incoming
messages are dropped by pymavlink's signature check and counted here (by message type).
"""

from __future__ import annotations

import threading
from collections import Counter, deque
from collections.abc import Callable
from typing import Any

import numpy as np
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.gc_freeze import frozen_collector
from mavsysid.flight.offline.effects import (
    config_truth_effects,
    effect_metadata,
    hidden_effect,
    motor_time_constant,
)
from mavsysid.flight.offline.imu_sensor import ImuSensor
from mavsysid.flight.simvehicle.autopilot import SimAutopilot
from mavsysid.flight.simvehicle.clock import SimClock, is_lockstep_stamp
from mavsysid.flight.simvehicle.commands import CommandHandler
from mavsysid.flight.simvehicle.link import COMPONENT_ID, SYSTEM_ID, mavlink, open_link
from mavsysid.flight.simvehicle.onboard_log import LogService, OnboardLog
from mavsysid.flight.simvehicle.params import ParameterProtocol, default_parameters
from mavsysid.flight.simvehicle.physics import CONTROL_DT_US, SimVehicle, TruthLog
from mavsysid.flight.simvehicle.services import (
    MISSION_MESSAGES,
    MissionProtocol,
    ftp_refusal,
    timesync_reply,
)
from mavsysid.flight.simvehicle.sim_session import SimSettings, SimSummary
from mavsysid.flight.simvehicle.telemetry import MessageScheduler, TelemetryBuilder, default_rates
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig

__all__ = ["SimEndpoint", "SimSettings", "SimSummary"]

M = mavlink
_COMMAND_IDS = frozenset((M.MAVLINK_MSG_ID_COMMAND_LONG, M.MAVLINK_MSG_ID_COMMAND_INT,
                          M.MAVLINK_MSG_ID_SET_MODE, M.MAVLINK_MSG_ID_PARAM_SET))
_SETPOINT_IDS = frozenset((M.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED,
                           M.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT,
                           M.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET))
_MAX_MESSAGES_PER_TICK = 200


class SimEndpoint:
    """A simulated vehicle on a MAVLink link.

    Parameters
    ----------
    connect : str
        ``udpout:HOST:PORT``, ``udpin:HOST:PORT`` or ``tcpin:HOST:PORT``.
    config : VehicleConfig
    settings : SimSettings
    """

    def __init__(self, connect: str, config: VehicleConfig,
                 settings: SimSettings | None = None) -> None:
        s = settings or SimSettings()
        self.settings, self.config = s, config
        true_theta = config.theta * np.asarray(s.theta_scale, dtype=float)
        self.link = open_link(connect)
        self._rejected: Counter[int] = Counter()
        if s.signing_key is not None:
            self.link.setup_signing(s.signing_key, sign_outgoing=True,
                                    allow_unsigned_callback=self._reject)
        imu = ImuSensor(config, s.seed, s.sensor_noise)
        try:
            truth = None if s.truth_log is None else TruthLog(
                s.truth_log, config, self._meta(connect, true_theta, imu), s.seed,
                s.sensor_noise)
        except BaseException:
            self.link.close()
            raise
        self.vehicle = SimVehicle(config, true_theta, s.start, seed=s.seed,
                                  sensor_noise=s.sensor_noise, truth_log=truth,
                                  effects=[hidden_effect(e) for e in s.hidden_effects], imu=imu)
        self.params = default_parameters(s.autopilot, config)
        self.autopilot = SimAutopilot(self.vehicle, s.autopilot, self.params, s.ekf_delay,
                                      deny_arm=s.deny_arm,
                                      land_detector_fails=s.land_detector_fails)
        self.scheduler = MessageScheduler(default_rates(s.autopilot, config.rotor_count))
        self.builder = TelemetryBuilder(self.autopilot)
        self.commands = CommandHandler(self.autopilot, self.scheduler, self.builder)
        self.param_protocol = ParameterProtocol(self.params,
                                                bytewise=s.autopilot is Autopilot.PX4)
        self.missions = MissionProtocol(self.autopilot.fence)
        self.onboard_log = OnboardLog(config, s.autopilot,
                                      lambda name: self.params.get(name, 0.0))
        self.log_service = LogService(self.onboard_log, lambda: self.autopilot.armed)
        self.clock = SimClock(CONTROL_DT_US * 1e-6, s.speedup, lockstep=s.lockstep)
        self._inbox: deque[Any] = deque()  # read while held for a lock-step ack
        self.received = self.sent = 0
        self.gcs_heartbeat_time: float | None = None
        self._stop = threading.Event()
        self._calls: list[Callable[[], None]] = []
        self._home_sent = False
        self._silent = False
        self._pilot_done = False
        self._weakened = False
        self._closed = False
        self._dispatch = {
            "COMMAND_LONG": self._on_command, "COMMAND_INT": self._on_command,
            "SET_MODE": self._on_set_mode, "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "PARAM_REQUEST_LIST": self._on_param, "PARAM_REQUEST_READ": self._on_param,
            "PARAM_SET": self._on_param, "REQUEST_DATA_STREAM": self._on_stream,
            "HEARTBEAT": self._on_heartbeat, "SYSTEM_TIME": self._on_system_time,
            "TIMESYNC": lambda m: self._send(timesync_reply(m, self.vehicle.time_us * 1000)),
            **dict.fromkeys(MISSION_MESSAGES, self._on_mission),
            "FILE_TRANSFER_PROTOCOL": lambda m: self._send(ftp_refusal(m)),
            **dict.fromkeys(("LOG_REQUEST_LIST", "LOG_REQUEST_DATA", "LOG_REQUEST_END",
                             "LOG_ERASE"), self._on_log),
        }

    # --- control from other threads -------------------------------------------------------
    def stop(self) -> None:
        """Ask the loop to finish (thread- and signal-safe)."""
        self._stop.set()

    def call_soon(self, fn: Callable[[], None]) -> None:
        """Run ``fn()`` in the loop's thread at the start of the next tick."""
        self._calls.append(fn)

    # --- the loop -------------------------------------------------------------------------
    def run(self) -> SimSummary:
        """Simulate until `stop` or the settings' duration; close everything; summarise."""
        clock, duration = self.clock, self.settings.duration
        status = "aborted"
        # Freeze what is alive now out of the cyclic collector: after a first run compiled
        # the kernels, numba's leftovers made full collections take 0.1–0.2 s, and ticks
        # that late set the vehicle oscillating on the setpoints that piled up meanwhile.
        with frozen_collector(collect_first=True):
            try:
                clock.start()
                while not self._stop.is_set():
                    while clock.due():
                        self._tick()
                        clock.advance()
                        if duration is not None and clock.tick_time >= duration - 1e-9:
                            self._stop.set()
                        if self._stop.is_set():
                            break
                    if clock.held:
                        self._read_while_held()
                    else:
                        clock.sleep_until_due()
                status = "complete"
            finally:
                summary = self.close(status)
        return summary

    def close(self, status: str = "complete") -> SimSummary:
        """Close the link and the truth log (idempotent); the session's summary."""
        summary = self.summary()
        if not self._closed:
            self._closed = True
            log = self.vehicle.truth_log
            if log is not None:
                log.finish(status, self._summary_meta(summary))
            self.link.close()
        return summary

    def _tick(self) -> None:
        ap, v = self.autopilot, self.vehicle
        t_us = v.time_us
        t = t_us * 1e-6
        ap.t = t
        while self._calls:
            self._calls.pop(0)()
        self._poll()
        self._faults(t)
        ap.update(t)
        if not self._home_sent and ap.position_ok():
            self._home_sent = True
            self._send(self.builder.build(M.MAVLINK_MSG_ID_HOME_POSITION))
        if ap.changed:
            ap.changed = False
            self._send(self.builder.heartbeat())
        while ap.events:
            severity, text = ap.events.popleft()
            self._send(M.MAVLink_statustext_message(severity, text.encode()[:50], 0, 0))
        for msg_id in self.scheduler.due(t_us):
            self._send(self.builder.build(msg_id))
        for msg in self.log_service.due():
            self._send(msg)
        self.onboard_log.record(t, ap.armed, ap.mode, v)
        if self.clock.frame_due(t_us) and not self._silent:
            # Last of the tick: the frame says "everything up to t_us has been sent".
            self._send(M.MAVLink_system_time_message(t_us, t_us // 1000))
            self.clock.frame_sent(t_us)
        v.step(ap.armed)

    def _faults(self, t: float) -> None:
        s = self.settings
        if s.silent_after is not None and t >= s.silent_after:
            self._silent = True
        if s.weak_motor is not None and t >= s.weak_motor[2] and not self._weakened:
            self._weakened = True
            motor, factor, _ = s.weak_motor
            self.vehicle.weaken(self.builder.outputs[motor - 1], factor)
        if s.pilot_mode is not None and not self._pilot_done and t >= s.pilot_mode[1]:
            self._pilot_done = True
            self.autopilot.set_mode(self.autopilot.modes_by_name[s.pilot_mode[0]])

    def _send(self, msg) -> None:
        if msg is None or self._silent:
            return
        try:
            self.link.mav.send(msg)
            self.sent += 1
        except OSError:
            pass  # no peer yet (TCP) or it went away: like a radio, keep going

    def _read_while_held(self) -> None:
        """Queue what arrives until the frame's acknowledgement (the next tick handles it)."""
        while True:
            try:
                msg = self.link.recv_msg()
            except OSError:
                msg = None
            if msg is None:
                if (t_us := self.clock.resend_due()) is not None and not self._silent:
                    # Lost if sent before the peer listened (the held start): again.
                    self._send(M.MAVLink_system_time_message(t_us, t_us // 1000))
                self.link.select(0.005)
                return
            self.clock.heard_peer()
            self._inbox.append(msg)
            if is_lockstep_stamp(msg):
                self.clock.acknowledge(msg.time_boot_ms * 1000)
                return

    def _poll(self) -> None:
        # Lock-stepped, the link is read only while held (`_read_while_held`), so that a
        # message takes effect at the tick after the acknowledgement that follows it.
        gated = self.clock.engaged and not self._silent
        for _ in range(_MAX_MESSAGES_PER_TICK):
            if self._inbox:
                msg = self._inbox.popleft()
            elif gated:
                return
            else:
                try:
                    msg = self.link.recv_msg()
                except OSError:
                    return
                if msg is None:
                    return
                self.clock.heard_peer()
            kind = msg.get_type()
            if kind == "BAD_DATA":
                continue
            self.received += 1
            handler = self._dispatch.get(kind)
            if handler is not None and _for_us(msg):
                handler(msg)

    # --- incoming messages ----------------------------------------------------------------
    def _ack(self, msg, command: int, result: int) -> None:
        self._send(M.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                 msg.get_srcComponent()))

    def _on_command(self, msg) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4]
        if msg.get_type() == "COMMAND_INT":
            p += [float(msg.x), float(msg.y), float(msg.z)]
        else:
            p += [msg.param5, msg.param6, msg.param7]
        result, replies = self.commands.command(msg.command, p)
        self._ack(msg, msg.command, result)
        for reply in replies:
            self._send(reply)

    def _on_set_mode(self, msg) -> None:
        # ArduPilot acknowledges SET_MODE with the message id as the command (#11).
        self._ack(msg, M.MAVLINK_MSG_ID_SET_MODE,
                  self.commands.set_mode_message(msg.base_mode, msg.custom_mode))

    def _on_setpoint(self, msg) -> None:
        self.autopilot.setpoint(msg)

    def _on_param(self, msg) -> None:
        for reply in self.param_protocol.handle(msg):
            self._send(reply)

    def _on_log(self, msg) -> None:
        for reply in self.log_service.handle(msg):
            self._send(reply)

    def _on_mission(self, msg) -> None:
        for reply in self.missions.handle(msg):
            self._send(reply)
        if "FENCE_TOTAL" in self.params:  # ArduPilot counts its stored fence points
            count = len(self.autopilot.fence.items)
            if self.params["FENCE_TOTAL"] != count:
                self.params.set("FENCE_TOTAL", count)

    def _on_stream(self, msg) -> None:
        self.commands.request_data_stream(msg.req_stream_id, msg.req_message_rate,
                                          bool(msg.start_stop))

    def _on_system_time(self, msg) -> None:
        if is_lockstep_stamp(msg):
            self.clock.acknowledge(msg.time_boot_ms * 1000)

    def _on_heartbeat(self, msg) -> None:
        if msg.type == M.MAV_TYPE_GCS:
            self.gcs_heartbeat_time = self.vehicle.time_us * 1e-6

    # --- signing and bookkeeping -----------------------------------------------------------
    def _reject(self, mav, msg_id: int) -> bool:
        """pymavlink's callback for unsigned or badly signed messages: count, refuse."""
        self._rejected[msg_id] += 1
        return False

    def rejected(self) -> dict[str, Any]:
        """Counts of messages dropped for their signature."""
        rejected = dict(self._rejected)  # one atomic copy: the loop thread may add to it
        total = sum(rejected.values())
        bad = self.link.mav.signing.badsig_count if self.settings.signing_key else 0
        names = {i: getattr(M.mavlink_map.get(i), "msgname", str(i)) for i in rejected}
        return {
            "total": total, "unsigned": total - bad, "bad_signature": bad,
            "commands": sum(n for i, n in rejected.items() if i in _COMMAND_IDS),
            "setpoints": sum(n for i, n in rejected.items() if i in _SETPOINT_IDS),
            "by_message": {names[i]: n for i, n in sorted(rejected.items())},
        }

    def summary(self) -> SimSummary:
        """The session so far."""
        sp = self.autopilot.setpoints
        log = self.vehicle.truth_log
        return SimSummary(clock=self.clock.stats(), received=self.received, sent=self.sent,
                          setpoints_received=sp.received, setpoints_applied=sp.applied,
                          rejected=self.rejected(),
                          truth_log=None if log is None else log.recorder.directory)

    def _meta(self, connect: str, true_theta: np.ndarray, imu: ImuSensor) -> dict[str, Any]:
        s = self.settings
        effects = [*config_truth_effects(self.config),
                   *(hidden_effect(e) for e in s.hidden_effects)]
        return {
            "source": "mavsysid sim", "connect": connect, "autopilot": s.autopilot.name.lower(),
            "seed": s.seed, "speedup": s.speedup, "lockstep": s.lockstep,
            "ekf_delay_s": s.ekf_delay,
            "start_enu_m": list(s.start), "sensor_noise": s.sensor_noise,
            "signing": s.signing_key is not None,
            "rates_hz": {"physics": 1000.0, "control": 500.0, "log": 200.0},
            "faults": _fault_meta(s),
            "pose_csv": "the truth plus a noise draw of the published pose's σ, at the log "
                        "rate (the messages sent draw their own noise)",
            "truth": {
                "parameters": dict(zip(PARAMETER_NAMES, map(float, true_theta), strict=True)),
                "theta_scale": list(s.theta_scale),
                "motor_time_constant_s": motor_time_constant(
                    effects, self.config.motor.time_constant),
                "effects": [effect_metadata(e) for e in effects if e.hidden],
                "imu": imu.truth(),
            },
            "model_effects": [effect_metadata(e) for e in effects if not e.hidden],
        }

    def _summary_meta(self, summary: SimSummary) -> dict[str, Any]:
        c = summary.clock
        return {"sim_time_s": c.sim_time, "wall_time_s": c.wall_time, "ticks": c.ticks,
                "mean_tick_rate_hz": c.mean_tick_rate, "max_tick_lag_s": c.max_lag,
                "late_ticks": c.late_ticks, "lockstep_frames": c.lockstep_frames,
                "lockstep_timeouts": c.lockstep_timeouts, "messages_received": summary.received,
                "messages_sent": summary.sent,
                "setpoints_received": summary.setpoints_received,
                "setpoints_applied": summary.setpoints_applied,
                "rejected_signatures": summary.rejected}


def _for_us(msg) -> bool:
    """Whether a message is addressed to this vehicle (or to everyone)."""
    system = getattr(msg, "target_system", 0)
    component = getattr(msg, "target_component", 0)
    return system in (0, SYSTEM_ID) and component in (0, COMPONENT_ID)


def _fault_meta(settings: SimSettings) -> dict[str, Any]:
    """The injected faults, for the truth log's meta.json."""
    out: dict[str, Any] = {}
    if settings.weak_motor is not None:
        motor, factor, onset = settings.weak_motor
        out["weak_motor"] = {"motor_output": motor, "thrust_factor": factor, "from_s": onset}
    if settings.silent_after is not None:
        out["silent_after_s"] = settings.silent_after
    if settings.pilot_mode is not None:
        out["pilot_mode"] = {"mode": settings.pilot_mode[0], "at_s": settings.pilot_mode[1]}
    if settings.deny_arm:
        out["deny_arm"] = True
    if settings.land_detector_fails:
        out["land_detector_fails"] = True
    return out
