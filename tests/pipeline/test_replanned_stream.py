"""Re-planning in flight: a 6 s opening, estimate, plan the rest, fly it, in one stream run
against `mavsysid sim` (lock-step, its own process); the belief the rest is planned from."""

from __future__ import annotations

import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import NoiseMet, ParameterEstimate
from mavsysid.flight.ground.continuation import FlightSoFar
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.motor_curve import pwm_from_rotor_speed
from mavsysid.formats.poselog import PoseLogWriter, read_pose_log
from mavsysid.formats.tlog import TlogWriter
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.pipeline.replanned_stream import (
    ReplanSettings,
    belief_after_opening,
    opening_belief,
    opening_log,
    positive_belief,
    prior_estimate,
    relative_covariance,
    rest_start,
    run_replanned_stream,
    snapshot_pose,
)
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import JobFailedError
from tests.support.stream_flights import BOX, SimProcess

SPEEDUP = 4.0
BUDGET = 14.0
#: A gentle 6 s figure: the opening.
OPENING = ExcitationSpec(duration=6.0, ramp=1.5, amplitude=(0.6, 0.5, 0.2))


def _opening(path):
    write_trajectory_file(path, trajectory_file_for(excitation_trajectory(OPENING),
                                                    load_vehicle("firefly"), box=BOX))
    return path


@pytest.mark.slow
def test_opening_then_replanned_rest_in_one_flight(tmp_path):
    """Both parts flown into one flight directory; the rest starts where the opening
    ended, lasts what the budget left, stays inside the box; the pose runs through."""
    port = free_udp_port()
    said: list[str] = []
    stream = StreamSettings(connect=f"udp:127.0.0.1:{port}", speedup=SPEEDUP, lockstep=True,
                            log_dir=tmp_path / "logs", box=BOX, heartbeat_timeout=300.0)
    replan = ReplanSettings(budget=BUDGET, planner=PlannerSettings(
        planning_time=math.inf, max_samples=300, refine_steps=50, seed=3))
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    f"{SPEEDUP:g}", "--theta-scale", "1,1.2,0.85,1.1,1.05,0.95"):
        outcome = run_replanned_stream(_opening(tmp_path / "opening.json"), stream, replan,
                                       say=said.append, progress=False)
    meta = read_meta(outcome.directory / "meta.json")
    assert meta["status"] == "complete", (meta.get("reason"), said)
    kinds = [s["kind"] for s in meta["segments"]]
    assert kinds == ["opening", "replanned", "end"], said
    rest = meta["segments"][1]
    assert rest["planner"]["budget"] == pytest.approx(BUDGET - 6.0)
    assert 0.0 < rest["duration"] <= BUDGET - 6.0 + 1e-6
    assert rest["hold_s"] > 0.0 and rest["planning_s"] > 0.0 and rest["estimation_s"] > 0.0
    theta = np.array(rest["estimate"]["theta"])
    sigma = np.array(rest["estimate"]["sigma"])
    assert np.all(np.isfinite(theta)) and np.all(sigma < 0.5 * theta)  # narrower than the prior
    met = rest["estimate"]["noise_met"]  # the rest was planned for the opening's noise
    assert met["pose_rate"] == pytest.approx(read_meta(
        outcome.directory / "meta.json")["stream"]["telemetry_rate_hz"], rel=0.2), met
    assert any("planned for the noise the opening met" in line for line in said), said
    end = excitation_trajectory(OPENING).flat_outputs(np.array([OPENING.duration]))
    assert rest["planner"]["start"][:3] == pytest.approx(end.position[0].tolist(), abs=1e-9)
    log = read_pose_log(outcome.directory / "pose.csv", 6)
    assert np.max(np.diff(log.t)) < 0.1
    assert np.max(np.linalg.norm(np.diff(log.position, axis=0), axis=1)) < 0.05
    w = rest["window"]
    on = (log.t >= w["start"]) & (log.t <= w["end"]) & (log.extra["t_traj"] >= 0.0)
    assert on.sum() == pytest.approx(50 * rest["duration"], rel=0.05)
    ref = np.column_stack([log.extra[k] for k in ("x_ref", "y_ref", "z_ref")])[on]
    assert np.all(ref >= np.array(BOX[:3])) and np.all(ref <= np.array(BOX[3:]))
    assert abs(log.position[-1, 2]) < 0.05  # landed
    assert meta["trajectory_window"]["end"] == pytest.approx(w["end"])


def test_snapshot_leaves_out_a_half_written_row(tmp_path):
    """The copy ends at the last complete line."""
    source = tmp_path / "live" / "pose.csv"
    source.parent.mkdir()
    source.write_text("t,x\n0.0,1.0\n0.1,1.")
    (tmp_path / "copy").mkdir()
    assert snapshot_pose(source, tmp_path / "copy").read_text() == "t,x\n0.0,1.0\n"


class _StepClock:
    """A tlog clock the test sets: µs since the Unix epoch."""

    now_us = 0

    def epoch_us(self) -> int:
        return self.now_us


BOOT_S, EPOCH_S, HOVER_STEP = 40.0, 1.7e9, 0.02


def _flight_without_esc(directory, config, rotors_in_pose):
    """A 4 s hover recorded as the streamer does: pose.csv (ESC rpm columns, here
    ``rotors_in_pose``) and flight.tlog from our writer with the motor outputs
    (SERVO_OUTPUT_RAW) and no ESC telemetry, its last record cut mid-write; the rotor
    speeds flown, per SERVO_OUTPUT_RAW time."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    rng = np.random.default_rng(7)
    directory.mkdir()
    mav, clock = m.MAVLink(None, srcSystem=1, srcComponent=1), _StepClock()
    tlog = TlogWriter(directory / "flight.tlog", clock)
    pose = PoseLogWriter(directory / "pose.csv", config.rotor_count)
    hover = math.sqrt(config.mass * 9.80665 / (config.rotor_count * config.theta[0]))
    t = BOOT_S + HOVER_STEP * np.arange(200)
    n = hover * (1.0 + 0.05 * rng.standard_normal((t.size, config.rotor_count)))
    pwm = np.rint(pwm_from_rotor_speed(n, config))
    for i, ti in enumerate(t):
        clock.now_us = round((EPOCH_S + ti + 0.003) * 1e6)
        ned = (0.2 * math.sin(ti), 0.2 * math.cos(ti), -1.0 - 0.1 * math.sin(2.0 * ti))
        q = (math.cos(0.05 * math.sin(ti)), 0.0, 0.0, math.sin(0.05 * math.sin(ti)))
        for msg in (m.MAVLink_heartbeat_message(2, 3, 0, 4, 4, 3),
                    m.MAVLink_servo_output_raw_message(round((ti - 0.004) * 1e6), 0,
                                                       *pwm[i].astype(int), 0, 0, 0, 0),
                    m.MAVLink_attitude_quaternion_message(round(ti * 1e3), *q, 0.0, 0.0, 0.0,
                                                          [0.0] * 4),
                    m.MAVLink_local_position_ned_message(round(ti * 1e3), *ned, 0.0, 0.0,
                                                         0.0)):
            tlog.write(msg.pack(mav))
        pose.write(ti, [ned[1], ned[0], -ned[2]], [q[0], 0.0, 0.0, -q[3]],
                   n[i] if rotors_in_pose else np.zeros(config.rotor_count))
    tlog.close()
    pose.close()
    with (directory / "flight.tlog").open("ab") as f:  # a record being written
        f.write(m.MAVLink_heartbeat_message(2, 3, 0, 4, 4, 3).pack(mav)[:5])
    return FlightSoFar(directory=directory, pose=directory / "pose.csv", config=config,
                       box=BOX, window_start=BOOT_S + 1.0, flown=3.0,
                       hover=(0.0, 0.0, 1.0, 0.0), segments=1), t - 0.004, n


def test_without_esc_rpm_the_opening_is_read_from_the_tlog_motor_outputs(tmp_path):
    """pose.csv's rotor speeds zero throughout: the opening is the tlog's snapshot, from
    the window's start, with the rotor speeds the motor outputs stand for."""
    config = load_vehicle("sitl_quad")
    so_far, t_servo, n = _flight_without_esc(tmp_path / "flight", config, False)
    (tmp_path / "copy").mkdir()
    log = opening_log(so_far, tmp_path / "copy")
    assert log == tmp_path / "copy" / "flight.tlog"
    assert log.read_bytes() == (so_far.directory / "flight.tlog").read_bytes()
    flight = load_flight(log, config, start=so_far.window_start)
    assert so_far.window_start <= flight.t[0] < so_far.window_start + 2 * HOVER_STEP
    expected = np.column_stack([np.interp(flight.t, t_servo, n[:, j])
                                for j in range(config.rotor_count)])
    # integer µs of PWM: about 0.2 % of a rotor speed at hover
    np.testing.assert_allclose(flight.rotor_speeds, expected, rtol=0.01)


def test_with_esc_rpm_the_opening_is_read_from_the_pose_log(tmp_path):
    """pose.csv with rotor speeds stays the opening's log."""
    config = load_vehicle("sitl_quad")
    so_far, _, _ = _flight_without_esc(tmp_path / "flight", config, True)
    (tmp_path / "copy").mkdir()
    assert opening_log(so_far, tmp_path / "copy") == tmp_path / "copy" / "pose.csv"


@pytest.mark.parametrize(("hover", "expected"), [
    ((0.3, -0.4, 1.5, 0.7), (0.3, -0.4, 1.5, 0.7)),  # far from the walls: the hold
    ((1.8, -1.2, 1.5, -0.1), (2.0 - 0.35, -1.2, 1.5, -0.1)),  # near x_max: pulled in
    ((-1.95, 1.9, 0.6, 0.0), (-2.0 + 0.35, 2.0 - 0.35, 0.5 + 0.35, 0.0)),  # a corner
])
def test_the_rest_starts_the_rotor_clearance_inside_the_box(hover, expected):
    """An opening ending nearer a wall than the rotor clearance is continued from the
    nearest point that far inside; otherwise from the hold itself."""
    config = load_vehicle("sitl_quad")  # rotors 0.35 m from the centre of gravity
    assert rest_start(hover, BOX, config) == pytest.approx(expected, abs=1e-9)


def test_budget_not_longer_than_the_opening_is_refused_before_connecting(tmp_path):
    """Exit 2, one line, no flight directory."""
    opening = _opening(tmp_path / "opening.json")
    result = subprocess.run(
        [sys.executable, "-m", "mavsysid", "stream", str(opening), "--replan-budget", "5",
         "--box", ",".join(str(v) for v in BOX), "--log-dir", str(tmp_path / "logs")],
        capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 2, result.stderr
    assert "--replan-budget 5: must exceed the opening's 6.0 s" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "logs").exists()


def _random_estimate(rng: np.random.Generator) -> ParameterEstimate:
    theta = load_vehicle("firefly").theta * rng.uniform(0.6, 1.4, 6)
    a = rng.normal(size=(6, 6)) * 0.05
    return ParameterEstimate(theta, (a @ a.T + 1e-4 * np.eye(6)) * np.outer(theta, theta))


def test_relative_covariance_is_the_posterior_seen_from_its_mean():
    rng = np.random.default_rng(11)
    estimate = _random_estimate(rng)
    rel = relative_covariance(estimate)
    config = load_vehicle("firefly").with_parameters(estimate.value)
    back = prior_estimate(config, PlannerSettings(prior_covariance=rel))
    np.testing.assert_allclose(back.value, estimate.value, rtol=1e-12)
    np.testing.assert_allclose(back.covariance, estimate.covariance, rtol=1e-10, atol=0.0)
    np.testing.assert_allclose(np.sqrt(np.diag(rel)), estimate.relative_sigma, rtol=1e-12)


def test_relative_covariance_refuses_a_non_positive_estimate():
    estimate = _random_estimate(np.random.default_rng(12))
    value = estimate.value.copy()
    value[1] = -value[1]
    with pytest.raises(JobFailedError, match="non-positive"):
        relative_covariance(ParameterEstimate(value, estimate.covariance))


def test_an_accepted_opening_estimate_is_the_belief():
    """An estimate that is not refused is the rest's belief, with no refusal."""
    estimate = _random_estimate(np.random.default_rng(3))
    prior = _random_estimate(np.random.default_rng(4))
    belief, refusal = belief_after_opening(lambda: estimate, prior)
    assert belief is estimate and refusal is None


def test_a_refused_opening_estimate_falls_back_to_the_prior():
    """A refused estimate leaves the prior belief and the refusal's first line."""
    prior = _random_estimate(np.random.default_rng(4))

    def refused() -> ParameterEstimate:
        raise JobFailedError("pose.csv: the parameter filter diverged\ndetails")

    belief, refusal = belief_after_opening(refused, prior)
    assert belief is prior and refusal == "pose.csv: the parameter filter diverged"


def test_default_prior_estimate_is_the_settings_relative_sigma():
    config = load_vehicle("firefly")
    est = prior_estimate(config, PlannerSettings(prior_relative_sigma=0.3))
    np.testing.assert_allclose(est.relative_sigma, 0.3, rtol=1e-12)
    assert np.count_nonzero(est.covariance - np.diag(np.diag(est.covariance))) == 0


def test_the_opening_belief_carries_the_noise_its_filter_met():
    """An accepted opening gives its final θ and its noise; a refused one neither."""
    estimate = _random_estimate(np.random.default_rng(5))
    prior = _random_estimate(np.random.default_rng(6))
    met = NoiseMet(0.05, 0.02, 50.0, 0.3, 0.004)
    result = SimpleNamespace(final=SimpleNamespace(theta=estimate), noise_met=met)
    assert opening_belief(lambda: result, prior) == (estimate, met, None)

    def refused():
        raise JobFailedError("the filter diverged")

    assert opening_belief(refused, prior) == (prior, None, "the filter diverged")


def test_a_parameter_answered_at_zero_keeps_the_prior_for_the_rest():
    """c_D at its bound (0) takes the prior's value and σ, without cross terms; the rest of
    the belief is unchanged and a positive belief passes as it is."""
    estimate = _random_estimate(np.random.default_rng(7))
    prior = _random_estimate(np.random.default_rng(8))
    value = estimate.value.copy()
    value[1] = 0.0
    belief, kept = positive_belief(ParameterEstimate(value, estimate.covariance), prior)
    assert kept == ("c_D",)
    assert belief.value[1] == prior.value[1]
    assert belief.covariance[1, 1] == prior.covariance[1, 1]
    assert np.count_nonzero(belief.covariance[1, :]) == 1
    others = [0, 2, 3, 4, 5]
    np.testing.assert_array_equal(belief.covariance[np.ix_(others, others)],
                                  estimate.covariance[np.ix_(others, others)])
    relative_covariance(belief)  # the planner can take it
    assert positive_belief(estimate, prior) == (estimate, ())
