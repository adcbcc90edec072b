"""Tests of the simulated vehicle's parts without a link: clock, scheduler, parameters,
reference shaper, setpoint semantics."""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.simvehicle.clock import SimClock
from mavsysid.flight.simvehicle.link import mavlink as M
from mavsysid.flight.simvehicle.params import ParameterProtocol, default_parameters
from mavsysid.flight.simvehicle.physics import DEFAULT_LIMITS, SimVehicle
from mavsysid.flight.simvehicle.reference import TARGET_DIM, hold_target, shape_step
from mavsysid.flight.simvehicle.services import ftp_refusal
from mavsysid.flight.simvehicle.setpoint_input import SetpointTracker
from mavsysid.flight.simvehicle.telemetry import MessageScheduler, default_rates
from mavsysid.vehicle.config import load_vehicle

LPN, AQ = M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
ESC1, ESC2 = M.MAVLINK_MSG_ID_ESC_TELEMETRY_1_TO_4, M.MAVLINK_MSG_ID_ESC_TELEMETRY_5_TO_8


class _SimulatedWall:
    """A wall clock that moves only when slept on, and by ``cost`` s per reading (a loop
    pass): the pacing is then the clock's logic alone, whatever the machine's load."""

    def __init__(self, cost: float = 2e-6) -> None:
        self.t, self.cost = 100.0, cost

    def now(self) -> float:
        self.t += self.cost
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += seconds


def _run_paced(clock: SimClock, wall: _SimulatedWall, seconds: float,
               stalls: dict[int, float]) -> None:
    """The sim loop's pacing (as `SimEndpoint` runs it) for ``seconds`` of wall time, with a
    stall of ``stalls[i]`` wall s after tick i."""
    clock.start()
    end = wall.t + seconds
    while wall.t < end:
        while clock.due():
            clock.advance()
            wall.sleep(stalls.get(clock.ticks, 0.0))
        clock.sleep_until_due()


def test_clock_catches_up_without_drift():
    """A loop that stalls runs the overdue ticks back to back: ticks = wall × speedup / dt."""
    wall = _SimulatedWall()
    clock = SimClock(0.002, speedup=2.0, wall=wall.now, sleep=wall.sleep)
    _run_paced(clock, wall, 0.3, {20: 0.05})  # 50 ms late: 50 ticks overdue at speedup 2
    stats = clock.stats()
    assert stats.max_lag >= 0.045  # the stall less the 1 ms to the next tick's time
    assert abs(stats.sim_time - 2.0 * stats.wall_time) < 0.002 * 2
    assert stats.mean_tick_rate == pytest.approx(500.0, rel=0.01)


def test_real_time_pacing_holds_500_hz_without_drift():
    """At speedup 1, over 2 s with seeded stalls of up to 30 ms: sim time follows the wall
    clock to within a tick (no drift), 500 Hz ticks, and no tick runs early (a simulated wall
    clock; ``bench/stream_timing.py`` runs the process in real time)."""
    rng = np.random.default_rng(7)
    stalls = {int(i): float(d) for i, d in zip(rng.integers(1, 1000, 20),
                                                 rng.uniform(0.0, 0.03, 20), strict=True)}
    wall = _SimulatedWall()
    clock = SimClock(0.002, wall=wall.now, sleep=wall.sleep)
    early = []
    start = wall.t
    clock.start()
    while wall.t < start + 2.0:
        while clock.due():
            early.append(clock.tick_time - (wall.t - start))
            clock.advance()
            wall.sleep(stalls.get(clock.ticks, 0.0))
        clock.sleep_until_due()
    stats = clock.stats()
    assert max(early) <= 1e-9  # no tick before its wall time
    assert abs(stats.sim_time - stats.wall_time) <= 0.002 + 1e-9
    assert stats.mean_tick_rate == pytest.approx(500.0, rel=0.002)
    assert stats.max_lag >= 0.02


def test_scheduler_due_times_are_multiples_of_the_interval():
    """Messages go out at multiples of their interval, in the fixed order; 250 Hz at most;
    the ESC 1–4 interval sets 5–8 too; an interval < 0 turns a message off."""
    sched = MessageScheduler(default_rates(Autopilot.ARDUPILOT, 6))
    assert sched.interval_us(AQ) == -1 and sched.interval_us(LPN) == 333333
    assert sched.set_interval(LPN, 20000, now_us=6000)
    assert sched.set_interval(AQ, 1000, now_us=6000)  # clamped to 4 ms
    assert sched.interval_us(AQ) == 4000
    assert sched.set_interval(ESC1, 20000, now_us=6000)
    assert sched.interval_us(ESC2) == 20000
    assert not sched.set_interval(12345, 20000, now_us=6000)
    sent = {LPN: [], AQ: [], ESC2: []}
    for t in range(6000, 1_006_000, 2000):
        due = sched.due(t)
        for i in sent:
            if i in due:
                sent[i].append(t)
        if LPN in due:
            assert due[-1] == LPN and due.index(AQ) < due.index(ESC1) < due.index(ESC2)
    assert all(t % 20000 == 0 for t in sent[LPN]) and len(sent[LPN]) == 50
    assert len(sent[AQ]) == 250 and len(sent[ESC2]) == 50
    sched.set_interval(LPN, -1, now_us=0)
    assert LPN not in sched.due(2_000_000) and sched.interval_us(LPN) == -1
    sched.set_interval(LPN, 0, now_us=0)
    assert sched.interval_us(LPN) == 333333


@pytest.mark.parametrize("autopilot", [Autopilot.ARDUPILOT, Autopilot.PX4])
def test_parameter_encoding_round_trips(autopilot):
    """Integer parameters: ArduPilot sends their value (C cast), PX4 their bytes; a PARAM_SET
    in the same encoding stores the number, rounded and clamped to the type."""
    table = default_parameters(autopilot, load_vehicle("firefly"))
    proto = ParameterProtocol(table, bytewise=autopilot is Autopilot.PX4)
    name = "DISARM_DELAY" if autopilot is Autopilot.ARDUPILOT else "COM_OBL_RC_ACT"
    p = table.at(table.index(name))
    sent = proto.encode(p)
    if autopilot is Autopilot.PX4:
        assert struct.unpack("<i", struct.pack("<f", sent))[0] == int(p.value)
        wire = struct.unpack("<f", struct.pack("<i", 2))[0]
    else:
        assert sent == p.value
        wire = 2.4
    msg = SimpleNamespace(get_type=lambda: "PARAM_SET", param_id=name, param_value=wire)
    (echo,) = proto.handle(msg)
    assert table[name] == 2.0 and echo.param_index == table.index(name)
    assert not table.set("NOT_A_PARAM", 1.0)


def test_shaper_passes_a_consistent_target_and_limits_a_jump():
    """A target moving with constant acceleration comes out unchanged; a 5 m position jump
    is followed at no more than the speed limit and reached without overshoot > 2 cm."""
    limits = np.array(DEFAULT_LIMITS)
    target, state, ref = np.zeros(TARGET_DIM), np.zeros(7), np.zeros(16)
    target[3:6] = (1.0, -0.5, 0.2)
    target[6:9] = (0.3, 0.1, -0.05)
    target[14:16] = 1.0
    state[3:6] = target[3:6]
    for i in range(1000):
        t = i * 0.002
        shape_step(target, state, limits, 0.002, ref)
        expected = np.array([1.0, -0.5, 0.2]) * t + 0.5 * np.array([0.3, 0.1, -0.05]) * t * t
        assert np.allclose(ref[0:3], expected, atol=1e-9)
        assert np.allclose(ref[6:9], (0.3, 0.1, -0.05), atol=1e-9)

    target, state = np.zeros(TARGET_DIM), np.zeros(7)
    hold_target(target, np.array([5.0, 0.0, 0.0]), 0.0)
    xs, vs = [], []
    for _ in range(5000):
        shape_step(target, state, limits, 0.002, ref)
        xs.append(ref[0])
        vs.append(ref[3])
    assert max(vs) <= limits[2] + 1e-9
    assert max(xs) < 5.02 and xs[-1] == pytest.approx(5.0, abs=1e-3)


def _msg(frame=1, mask=0, x=0.0, y=0.0, z=0.0, vx=0.0, vy=0.0, vz=0.0, afx=0.0, afy=0.0,
         afz=0.0, yaw=0.0, yaw_rate=0.0):
    return SimpleNamespace(coordinate_frame=frame, type_mask=mask, x=x, y=y, z=z, vx=vx, vy=vy,
                           vz=vz, afx=afx, afy=afy, afz=afz, yaw=yaw, yaw_rate=yaw_rate)


@pytest.fixture(scope="module")
def flying():
    """A vehicle in the air at ENU (0, 0, 2), heading north (ENU yaw π/2)."""
    vehicle = SimVehicle(load_vehicle("quad_x"), load_vehicle("quad_x").theta, yaw=math.pi / 2)
    vehicle.lift_off()
    vehicle.y[2] = 2.0
    vehicle.shaper[2] = 2.0
    return vehicle


def test_ardupilot_type_mask_groups_and_frames(flying):
    """ArduPilot: each group is all or nothing; position+acceleration without velocity
    stops; body frames rotate by the heading; yaw and yaw rate convert NED → ENU."""
    tracker = SetpointTracker(flying, ardupilot=True)
    assert tracker.receive(_msg(mask=0b110111000000, x=1.0, y=2.0, z=-3.0, vx=0.5), 0.0, True)
    np.testing.assert_allclose(flying.target[0:3], (2.0, 1.0, 3.0))
    np.testing.assert_allclose(flying.target[3:6], (0.0, 0.5, 0.0))
    assert flying.target[14] == 1.0
    # Any bit of a group drops the whole group: one ignored x drops the position.
    assert tracker.receive(_msg(mask=0b110111000001, x=9.0, vx=0.5), 0.0, True)
    assert flying.target[14] == 0.0
    # Position + acceleration without velocity: refused, the vehicle stops (holds).
    assert not tracker.receive(_msg(mask=0b110000111000, x=1.0, afx=1.0), 0.0, True)
    assert flying.target[14] == 1.0 and np.all(flying.target[3:9] == 0.0)
    # BODY_OFFSET_NED (9): 1 m forward while heading north is 1 m north of the vehicle;
    # yaw 0.5 rad clockwise relative to the heading.
    assert tracker.receive(_msg(frame=9, mask=0b100111111000, x=1.0, yaw=0.5), 0.0, True)
    np.testing.assert_allclose(flying.target[0:3], flying.position + (0.0, 1.0, 0.0),
                               atol=1e-9)
    assert flying.target[12] == pytest.approx(math.pi / 2 - 0.5)
    assert tracker.receive(_msg(mask=0b000111111000, x=0.0, yaw=0.0, yaw_rate=0.3), 0.0,
                           True)
    assert flying.target[12] == pytest.approx(math.pi / 2) and flying.target[13] == -0.3
    # A frame ArduPilot does not take stops the vehicle; not in GUIDED: ignored.
    assert not tracker.receive(_msg(frame=6, mask=0b110111000111, vx=1.0), 0.0, True)
    assert not tracker.receive(_msg(mask=0b110111000111, vx=1.0), 0.0, False)


def test_jerk_is_estimated_from_successive_acceleration_setpoints(flying):
    """Acceleration setpoints at a steady 50 Hz (receipt quantised to ticks) give their
    finite-difference jerk, which is extrapolated for a short while only."""
    tracker = SetpointTracker(flying, ardupilot=True)
    receipts = [0.0, 0.020, 0.040, 0.062, 0.080, 0.100, 0.120, 0.142, 0.160]
    for k, t in enumerate(receipts):
        a = 0.5 * (k * 0.02)  # jerk 0.5 m/s³ north, sampled every 20 ms
        assert tracker.receive(_msg(mask=0b110000000000, x=0.0, y=0.0, z=-2.0, afx=a), t, True)
    assert flying.target[10] == pytest.approx(0.5, rel=0.12)
    assert 0.0 < flying.target[16] <= 0.1


def test_px4_setpoints_count_towards_the_offboard_stream(flying):
    """PX4: frames 1 and 8 count towards the stream in any mode; > 2 Hz for > 1 s opens
    OFFBOARD; a gap longer than 0.5 s restarts the count; other frames are ignored."""
    tracker = SetpointTracker(flying, ardupilot=False)
    for k in range(12):
        tracker.receive(_msg(mask=0b110111111000, z=-2.0), 0.1 * k, False)
    assert tracker.streaming(1.15)
    assert not tracker.streaming(1.7)  # stale
    tracker.receive(_msg(frame=7, mask=0b110111111000), 2.5, False)
    assert not tracker.streaming(2.5)
    for k in range(4):
        tracker.receive(_msg(frame=8, mask=0b110111111000), 3.0 + 0.3 * k, False)
    assert not tracker.streaming(3.9)
    tracker.receive(_msg(frame=8, mask=0b110111111000), 4.2, False)
    assert tracker.streaming(4.2)


def test_ftp_is_refused_so_ground_stations_fall_back():
    """An FTP OpenFileRO gets a NAK (file not found) with the request's opcode and seq + 1."""
    payload = list(struct.pack("<HBBBBBBI", 7, 0, 4, 0, 0, 0, 0, 0)) + [0] * 239
    req = SimpleNamespace(payload=payload, get_srcSystem=lambda: 255,
                          get_srcComponent=lambda: 190)
    reply = ftp_refusal(req)
    seq, _, opcode, size, req_opcode = struct.unpack_from("<HBBBB", bytes(reply.payload))
    assert (seq, opcode, size, req_opcode, reply.payload[12]) == (8, 129, 1, 4, 10)
    assert (reply.target_system, reply.target_component) == (255, 190)
