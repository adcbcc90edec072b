"""A continued flight: more trajectories flown after the first in one stream run, against
`mavsysid sim` in its own process (lock-step), the streamer in this process."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.flight.ground.continuation import FlightSoFar, NextSegment, combined_statistics
from mavsysid.flight.ground.stream_session import StreamSettings
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
from mavsysid.pipeline.stream import run_stream
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import JobFailedError
from tests.support.stream_flights import BOX, SimProcess

SPEEDUP = 4.0
#: A short figure (the default ramps need 6 s alone), smaller so that it stays gentle.
OPENING = ExcitationSpec(duration=6.0, ramp=1.5, amplitude=(0.6, 0.5, 0.2))


def _shifted(trajectory: PiecewisePolynomial, dx: float) -> PiecewisePolynomial:
    coeffs = np.array(trajectory.position_coeffs, dtype=float)
    coeffs[:, 0, 0] += dx
    return PiecewisePolynomial(np.asarray(trajectory.durations), coeffs,
                               np.asarray(trajectory.yaw_coeffs))


def _fly(tmp_path, continuation):
    """Fly a 6 s figure with ``continuation``; (outcome or error, flight dir, messages)."""
    opening = tmp_path / "opening.json"
    write_trajectory_file(opening, trajectory_file_for(excitation_trajectory(OPENING),
                                                       load_vehicle("firefly"), box=BOX))
    port = free_udp_port()
    said: list[str] = []
    settings = StreamSettings(connect=f"udp:127.0.0.1:{port}", speedup=SPEEDUP,
                              log_dir=tmp_path / "logs", lockstep=True, box=BOX,
                              heartbeat_timeout=300.0)
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    f"{SPEEDUP:g}"):
        try:
            result = run_stream(opening, settings, say=said.append, progress=False,
                                continuation=continuation)
        except JobFailedError as error:
            result = error
    (directory,) = [p for p in (tmp_path / "logs").iterdir() if p.is_dir()]
    return result, directory, said


@pytest.mark.slow
def test_a_continuation_is_flown_in_the_same_recording(tmp_path):
    """The second trajectory is flown after a hold in which the callback ran; one pose log
    runs through both without a gap, the second part's setpoints inside the box."""
    seen: list[FlightSoFar] = []
    prefix_rows: list[int] = []

    def continuation(so_far: FlightSoFar) -> NextSegment | None:
        seen.append(so_far)
        if len(seen) > 1:
            return None
        prefix_rows.append(len(read_pose_log(so_far.pose, 6)))
        # The vehicle holds, and is recorded, while the callback works: wait for rows
        # that arrive during the hold (so the hold also lasts some vehicle time).
        deadline = time.monotonic() + 120.0
        while len(read_pose_log(so_far.pose, 6)) <= prefix_rows[0] + 5:
            assert time.monotonic() < deadline, "no pose rows recorded during the hold"
            time.sleep(0.05)
        return NextSegment(excitation_trajectory(replace(OPENING, duration=8.0)), "second",
                           {"note": "from the test"})

    outcome, directory, said = _fly(tmp_path, continuation)
    assert not isinstance(outcome, Exception), said
    meta = read_meta(directory / "meta.json")
    assert meta["status"] == "complete", meta.get("reason")
    assert [s["kind"] for s in meta["segments"]] == ["opening", "second", "end"]
    second = meta["segments"][1]
    assert second["note"] == "from the test" and second["hold_s"] > 0.0
    assert seen[0].flown == pytest.approx(6.0) and seen[1].flown == pytest.approx(14.0)
    assert seen[0].window_start == pytest.approx(meta["trajectory_window"]["start"])
    assert prefix_rows[0] > 50 * 8  # the opening's rows were on disk when asked
    log = read_pose_log(directory / "pose.csv", 6)
    assert np.max(np.diff(log.t)) < 0.1
    assert np.max(np.linalg.norm(np.diff(log.position, axis=0), axis=1)) < 0.05
    w = second["window"]
    assert meta["trajectory_window"]["end"] == pytest.approx(w["end"])
    on = (log.t >= w["start"]) & (log.t <= w["end"]) & (log.extra["t_traj"] >= 0.0)
    assert on.sum() == pytest.approx(50 * 8, rel=0.05)
    ref = np.column_stack([log.extra[k] for k in ("x_ref", "y_ref", "z_ref")])[on]
    assert np.all(ref >= np.array(BOX[:3])) and np.all(ref <= np.array(BOX[3:]))
    assert abs(log.position[-1, 2]) < 0.05  # landed


@pytest.mark.slow
def test_a_refused_continuation_lands(tmp_path):
    """A trajectory leaving the box is refused before one setpoint of it is sent: the
    vehicle lands and the run fails with one line."""
    def continuation(so_far: FlightSoFar) -> NextSegment:
        return NextSegment(_shifted(excitation_trajectory(replace(OPENING, duration=8.0)), 3.0),
                           "outside")

    error, directory, said = _fly(tmp_path, continuation)
    assert isinstance(error, JobFailedError)
    assert "outside trajectory refused" in str(error) and "\n" not in str(error)
    assert "landed and disarmed" in said
    meta = read_meta(directory / "meta.json")
    assert meta["status"] == "aborted" and "refused" in meta["reason"]
    assert meta["segments"][-1]["refused"]
    log = read_pose_log(directory / "pose.csv", 6)
    assert np.all(log.extra["x_ref"] <= BOX[3])
    assert np.all(log.extra["t_traj"] <= 6.0 + 1e-6)  # nothing of the second was sent
    assert abs(log.position[-1, 2]) < 0.05


def test_combined_statistics_sum_counts_and_keep_worst_deviation():
    """Counts add; the p99 and max deviations are the worse segment's."""
    a = {"sent": 100, "dropped": 1, "late": 0, "nominal_rate_hz": 50.0, "rate_hz": 50.0,
         "period_deviation_mean_s": 1e-4, "period_deviation_p99_s": 1e-3,
         "period_deviation_max_s": 2e-3}
    b = {**a, "sent": 300, "dropped": 2, "rate_hz": 49.0, "period_deviation_p99_s": 5e-4,
         "period_deviation_max_s": 4e-3}
    out = combined_statistics([a, b])
    assert (out["sent"], out["dropped"]) == (400, 3)
    assert out["rate_hz"] == pytest.approx((100 * 50.0 + 300 * 49.0) / 400)
    assert out["period_deviation_p99_s"] == 1e-3 and out["period_deviation_max_s"] == 4e-3
