"""The motor outputs watched in flight (`MotorWatch`): fed SERVO_OUTPUT_RAW messages as an
autopilot sends them at 50 Hz, built from thrust shares through the vehicle file's motor
curve; and flights of the simulated vehicle with a weak motor."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from mavsysid.flight.ground.motor_watch import MotorFault, MotorWatch
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.mavlink_setup import load_mavutil
from mavsysid.vehicle.config import load_vehicle

from tests.support.stream_flights import SimProcess, export_excitation, flight_dir, run_stream

QUAD = load_vehicle("quad_x")  # outputs in rotor order; mirrors 1↔3, 2↔4
HEXA = load_vehicle("firefly")  # mirrors 1↔4, 2↔5, 3↔6, which spin opposite ways
RATE = 50.0


def _pwm(config, share: np.ndarray) -> list[int]:
    """The outputs (µs) that ask for thrust shares ``share`` of full thrust."""
    e, m = config.motor.thrust_expo, config.motor
    u = (-(1 - e) + np.sqrt((1 - e) ** 2 + 4 * e * np.clip(share, 0, 1))) / (2 * e)
    return [round(v) for v in m.pwm_min + u * (m.pwm_max - m.pwm_min)]


def _feed(watch: MotorWatch, config, shares, t0: float = 0.0) -> float:
    """Send one SERVO_OUTPUT_RAW per row of ``shares`` at 50 Hz; the last time."""
    mavlink = load_mavutil().mavlink
    t = t0
    for i, row in enumerate(np.atleast_2d(shares)):
        t = t0 + i / RATE
        raw = _pwm(config, np.asarray(row)) + [0] * (16 - len(row))
        watch.on_message(mavlink.MAVLink_servo_output_raw_message(int(t * 1e6), 0, *raw), t)
    return t


def _compensated(config, f: np.ndarray, weak: dict[int, float]) -> np.ndarray:
    """The shares a pseudo-inverse mixer with integrators settles on when motor i makes
    F_i of its share: f + A⁺ z such that A (F ∘ (f + A⁺ z)) = A f, with A the allocation
    (collective, roll, pitch, yaw) in share units."""
    p, eps = config.rotor_positions, config.rotor_directions
    a = np.vstack([np.ones(eps.size), p[:, 1], -p[:, 0], 0.016 * eps])
    pinv = np.linalg.pinv(a)
    factor = np.ones(eps.size)
    for motor, f_i in weak.items():
        factor[motor] = f_i
    z = np.linalg.solve(a @ np.diag(factor) @ pinv, (a @ (f * (1.0 - factor)).T))
    return f + (pinv @ z).T


def _flight(config, seconds: float, weak: dict[int, float] | None = None,
            yaw: float = 0.0, seed: int = 0) -> np.ndarray:
    """Thrust shares of a hovering vehicle manoeuvring: roll and pitch torques at 1–3 Hz,
    a yaw torque swinging at 0.25 Hz (``yaw`` of the share), and weak motors (index → F)
    compensated as the autopilot's mixer and integrators do."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / RATE)
    angles = np.arctan2(config.rotor_positions[:, 1], config.rotor_positions[:, 0])
    f = np.full((t.size, config.rotor_count), 0.3)
    for freq, phase in zip(rng.uniform(1, 3, 2), rng.uniform(0, 2 * np.pi, 2), strict=True):
        f += 0.08 * np.outer(np.sin(2 * np.pi * freq * t + phase), np.cos(angles - phase))
    f += yaw * np.outer(np.sin(2 * np.pi * 0.25 * t), config.rotor_directions)
    return _compensated(config, f, weak) if weak else f


def _watch(config):
    said: list[str] = []
    watch = MotorWatch(config, said.append)
    watch.active = True
    return watch, said


def test_a_healthy_quad_manoeuvring_draws_nothing():
    watch, said = _watch(QUAD)
    _feed(watch, QUAD, _flight(QUAD, 20.0))
    assert said == [] and watch.peak_imbalance < 1.1


def test_a_weak_motor_is_reported_once_naming_it_and_its_mirror():
    """Motor 2 asked for 1/0.7 of its share: reported after 2 s, with the ratio 1.43."""
    watch, said = _watch(QUAD)
    _feed(watch, QUAD, _flight(QUAD, 20.0, weak={1: 0.7}))
    (line,) = said
    assert line.startswith("warning: motor 2 is asked for 1.") and "motor 4, its mirror" in line
    assert watch.peak_imbalance == pytest.approx(1 / 0.7, rel=0.05)
    assert watch.findings[0]["motor_output"] == 2 and watch.findings[0]["kind"] == "imbalance"


def test_a_motor_at_less_than_half_aborts():
    watch, _said = _watch(QUAD)
    with pytest.raises(MotorFault, match=r"motor 1 is asked for 2\.2"):
        _feed(watch, QUAD, _flight(QUAD, 20.0, weak={0: 0.45}))
    assert not watch.active and watch.findings[-1]["aborted"]


def test_a_hexa_swinging_in_yaw_is_no_weak_motor_but_a_weak_one_is():
    """Opposite rotors of a hexa spin opposite ways: a yaw swing of 0.1 of full thrust loads
    them 1.3 : 1 over seconds; the yaw share's swing taken out, it draws nothing, while a
    steady 70 % motor is reported (its ratio about 1/0.7, the swing's remainder on top) and
    no other."""
    watch, said = _watch(HEXA)
    _feed(watch, HEXA, _flight(HEXA, 20.0, yaw=0.1))
    assert said == [] and watch.peak_imbalance < 1.2
    raw = _flight(HEXA, 20.0, yaw=0.1)
    window = raw[: int(2 * RATE)].mean(axis=0)
    assert max(window[i] / window[j] for i, j in enumerate((3, 4, 5, 0, 1, 2))) > 1.3
    watch, said = _watch(HEXA)
    _feed(watch, HEXA, _flight(HEXA, 20.0, weak={2: 0.7}, yaw=0.1))
    assert [line.split(" is asked")[0] for line in said] == ["warning: motor 3"]
    assert 1.3 < watch.peak_imbalance < 2.0


def test_saturation_is_reported_and_aborts_after_a_second():
    """Every motor at the top (a climb the vehicle cannot make): each reported once from
    0.25 s, the flight aborted at 1 s."""
    watch, said = _watch(QUAD)
    shares = _flight(QUAD, 5.0)
    shares[50:70] = 1.0  # 0.4 s at the top
    _feed(watch, QUAD, shares)
    assert said == [f"warning: motor {i} at the top of its range for 0.26 s" for i in range(1, 5)]
    shares[100:170] = 1.0  # 1.4 s
    with pytest.raises(MotorFault, match=r"motor 1 at the top of its range for 1\.0 s"):
        _feed(watch, QUAD, shares, t0=10.0)


def test_outputs_that_are_not_pwm_switch_the_watch_off_once():
    """DShot or DroneCAN commands (about 4300–4700) are not µs: one line, then nothing."""
    watch, said = _watch(QUAD)
    mavlink = load_mavutil().mavlink
    for i in range(200):
        raw = [4300 + i, 4700, 4500, 4400] + [0] * 12
        watch.on_message(mavlink.MAVLink_servo_output_raw_message(i, 0, *raw), i / RATE)
    (line,) = said
    assert "4300..4700 are not in the vehicle file's PWM range [1000, 2000]" in line
    assert watch.off_reason is not None and watch.findings == []


def test_nothing_is_judged_on_the_ground():
    watch, said = _watch(QUAD)
    watch.active = False
    _feed(watch, QUAD, _flight(QUAD, 5.0, weak={0: 0.3}))
    assert said == [] and watch.peak_imbalance == 1.0


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize(("fault", "code"), [("0.7", 0), ("0.45@20", 3)])
def test_a_weak_motor_of_the_simulated_vehicle(tmp_path, fault, code):
    """`mavsysid sim --fault weak-motor:1=F`: at 70 % from the start the streamer reports
    motor 1 against motor 3 and the tracking past half its (tight) limit, and flies on; at
    45 % from 20 s (in the air) it aborts, holds and lands, and says why (exit 3)."""
    factor = float(fault.split("@")[0])
    tracking = "0.12" if code == 0 else "1"
    trajectory = export_excitation(tmp_path / "figure.json", 12.0, vehicle="quad_x")
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--vehicle",
                    "quad_x", "--speedup", "8", "--fault", f"weak-motor:1={fault}"):
        done = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup", "8",
                          "--vehicle", "quad_x", "--max-tracking-error", tracking, "--log-dir",
                          str(logs), cwd=tmp_path)
    err = done.stderr
    meta = json.loads((flight_dir(logs) / "meta.json").read_text())
    assert done.returncode == code, err[-3000:]
    assert "motor 1 is asked for" in err and "motor 3, its mirror" in err
    assert "landed and disarmed" in err
    peak = meta["motor_watch"]["peak_imbalance"]
    if code == 0:
        assert peak == pytest.approx(1 / factor, rel=0.05)
        assert "tracking error" in err and "past 50 % of the 0.12 m limit" in err
    else:  # aborted as the window's ratio passes the limit on its way to 1/F
        assert 2.0 <= peak <= 1 / factor
        assert meta["status"] == "aborted" and "motor 1" in meta["reason"]
        assert "aborted to BRAKE" in err and math.isfinite(meta["samples"])
