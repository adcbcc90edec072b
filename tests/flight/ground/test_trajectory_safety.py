"""Nothing unsafe leaves the streamer: trajectory files checked before connecting, and every
setpoint checked before it is sent (`mavsysid.flight.ground.trajectory_safety`, `setpoints`)."""

from __future__ import annotations

import json
import re
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.flight.ground.setpoints import Setpoint, SmoothMove
from mavsysid.flight.ground.stream_session import load_plan
from mavsysid.flight.ground.trajectory_safety import (
    check_trajectory,
    flight_limits,
    operator_box,
)
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.formats.trajectory_file import (
    parse_trajectory,
    read_trajectory,
    trajectory_file_for,
)
from mavsysid.vehicle.config import load_vehicle, vehicle_to_toml
from mavsysid.vehicle.frames import ned_to_enu, yaw_rate_ned_to_enu

from mavsysid.errors import InputError, JobFailedError
from tests.support.mutated_trajectories import (
    MUTATIONS,
    SentSetpoint,
    mutated_files,
    scale_time,
    streamed_setpoints,
    unsafe,
)
from tests.support.stream_flights import SimProcess, flight_dir, read_tlog, run_stream
from tests.support.trajectories import ground_descent

BOX = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)
LOW_BOX = (-2.0, -2.0, 0.05, 2.0, 2.0, 2.5)


@pytest.fixture(scope="module")
def firefly():
    return load_vehicle("firefly")


@pytest.fixture(scope="module")
def bases(firefly):
    """Shipped trajectories: excitation figures of several durations and shapes, a descent."""
    figures = [excitation_trajectory(ExcitationSpec(duration=d)) for d in (10.0, 12.0, 20.0)]
    figures.append(excitation_trajectory(ExcitationSpec(duration=14.0, amplitude=(0.8, 0.6,
                                                                                  0.3))))
    docs = [trajectory_file_for(t, firefly, "excitation", BOX) for t in figures]
    return docs + [trajectory_file_for(ground_descent(0.6, 1.5, 1), firefly, "test", BOX)]


def _one_line(error: Exception) -> str:
    text = str(error)
    assert "\n" not in text and text, repr(text)
    return text


def _judge(tmp_path, name, text, config):
    """("refused", message) or ("accepted", sent setpoints, unsafe list, guard stop)."""
    path = tmp_path / f"{name}.json"
    path.write_text(text)
    try:
        plan, _config, box = load_plan(path, "firefly", BOX)
    except (InputError, JobFailedError) as error:
        return ("refused", _one_line(error))
    sent, stopped = streamed_setpoints(plan.trajectory, config, box)
    return ("accepted", sent, unsafe(sent, config, BOX), stopped)


def _fly_all(tmp_path, bases, config, count, seed):
    tally, stops, bad = Counter(), [], []
    for name, text in mutated_files(bases, count, seed):
        verdict = _judge(tmp_path, name, text, config)
        tally[verdict[0]] += 1
        if verdict[0] == "accepted":
            _, sent, problems, stopped = verdict
            assert sent, name
            bad += [f"{name} {p}" for p in problems]
            if stopped:
                stops.append(f"{name}: {stopped}")
    return tally, stops, bad


@pytest.mark.slow
def test_mutated_files_send_no_unsafe_setpoint(tmp_path, bases, firefly, capsys):
    """150 seeded mutated files: each refused before connecting in one line, or flown through
    the streamer's setpoint path with 0 setpoints outside the box or beyond the limits."""
    tally, stops, bad = _fly_all(tmp_path, bases, firefly, 150, seed=19)
    with capsys.disabled():
        print(f"\nmutated files 150: refused {tally['refused']}, accepted "
              f"{tally['accepted']}, guard stops {len(stops)}, unsafe setpoints {len(bad)}")
    assert bad == []
    # The check before connecting is complete: the last line of defence never fires.
    assert stops == []
    # Both outcomes occur, so the test can tell a refusal from a flight.
    assert tally["refused"] >= 50 and tally["accepted"] >= 20


def test_a_few_mutated_files(tmp_path, bases, firefly):
    """The fast version: one file per mutation."""
    tally, stops, bad = _fly_all(tmp_path, bases, firefly, len(MUTATIONS), seed=7)
    assert bad == [] and stops == []
    assert tally["refused"] and tally["accepted"]


def test_unmutated_shipped_trajectories_are_accepted(tmp_path, bases, firefly):
    for i, doc in enumerate(bases):
        path = tmp_path / f"base{i}.json"
        path.write_text(json.dumps(doc))
        box = LOW_BOX if doc["kind"] == "test" else BOX
        load_plan(path, "firefly", box)


@pytest.mark.parametrize(("mutation", "words"), [
    ("compress", "speed"), ("yaw_ramp", "yaw rate"), ("jump", "leaves the box"),
    ("swap", "jumps by"), ("kink", "acceleration jumps by 0.1 m/s²")])
def test_refusal_names_quantity_value_limit_and_time(tmp_path, bases, firefly, mutation,
                                                     words):
    """One line naming the quantity, its value, the limit and the time in the file."""
    doc = json.loads(json.dumps(bases[1]))
    rng = np.random.default_rng(0)
    if mutation == "compress":
        doc = scale_time(doc, 4.0)
    elif mutation == "yaw_ramp":
        for s in doc["segments"]:
            s["yaw"][1] += 50.0
            s["yaw"][0] += 50.0 * (sum(x["duration"] for x in doc["segments"][
                :doc["segments"].index(s)]))
    elif mutation == "kink":
        doc["segments"][2]["position"][0][2] += 0.05  # acceleration +0.1 m/s² at its start
    else:
        doc = MUTATIONS[mutation](doc, rng)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(JobFailedError) as info:
        load_plan(path, "firefly", BOX)
    message = _one_line(info.value)
    assert message.startswith("flight refused: ") and words in message, message
    assert "t = " in message


def test_file_box_never_widens_the_operators(tmp_path, bases, firefly):
    """A huge box in the file never widens --box or the vehicle's box: it only narrows."""
    doc = json.loads(json.dumps(bases[1]))
    doc["box"] = [-1000.0, -1000.0, -1000.0, 1000.0, 1000.0, 1000.0]
    small = (-1.0, -1.0, 0.5, 1.0, 1.0, 2.5)  # the figure spans x ±1.3
    assert operator_box(small, BOX, doc["box"], "f") == (small, "--box")
    assert operator_box(None, small, doc["box"], "f")[0] == small
    with pytest.raises(InputError, match="no flight box from the operator"):
        operator_box(None, None, doc["box"], "f")
    narrow = (-0.5, -3.0, 1.0, 3.0, 0.5, 2.0)
    box, source = operator_box(small, None, narrow, "f")
    assert box == (-0.5, -1.0, 1.0, 1.0, 0.5, 2.0) and source.endswith("narrowed by the "
                                                                        "trajectory file's box")
    with pytest.raises(InputError, match="does not overlap --box"):
        operator_box(small, None, (5.0, 5.0, 5.0, 6.0, 6.0, 6.0), "f")
    path = tmp_path / "wide.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(JobFailedError, match="leaves the box"):
        load_plan(path, "firefly", small)
    # A vehicle file with its own box: used when no --box is given.
    vehicle = tmp_path / "boxed.toml"
    vehicle.write_text(vehicle_to_toml(replace(firefly, box=None))
                       + "\n[flight]\nbox = [-1.0, -1.0, 0.5, 1.0, 1.0, 2.5]\n")
    with pytest.raises(JobFailedError,
                       match=r"leaves the box .* \(box: the vehicle's \[flight\] box\)$"):
        load_plan(path, vehicle, None)
    # The configuration embedded in the trajectory file is the file's: its box is no
    # operator's box.
    with pytest.raises(InputError, match="no flight box from the operator"):
        load_plan(path, None, None)


def _inside(inner, outer) -> bool:
    return all(inner[k] >= outer[k] - 1e-12 for k in range(3)) and all(
        inner[k] <= outer[k] + 1e-12 for k in range(3, 6))


def test_no_file_box_widens_the_operators_box(tmp_path, bases, firefly):
    """Every mutated file (the mutations above, seeded) under a seeded operator box, given
    as --box or as the vehicle's [flight] box: the box in use lies inside the operator's,
    and every setpoint the streamer would send for an accepted file lies inside it too."""
    rng = np.random.default_rng(23)
    vehicle = tmp_path / "boxed.toml"
    accepted = refused = 0
    for name, text in mutated_files(bases, 2 * len(MUTATIONS), seed=31):
        try:
            file_box = json.loads(text).get("box")
        except (ValueError, AttributeError):
            file_box = None
        lo = rng.uniform([-3.0, -3.0, 0.0], [-1.0, -1.0, 0.6])
        operator = tuple(float(v) for v in (*lo, *(lo + rng.uniform(2.5, 5.0, 3))))
        by_vehicle = bool(rng.integers(2))
        if by_vehicle:
            vehicle.write_text(vehicle_to_toml(replace(firefly, box=operator)))
        path = tmp_path / f"{name}.json"
        path.write_text(text)
        try:
            plan, _config, box = load_plan(path, vehicle if by_vehicle else "firefly",
                                           None if by_vehicle else operator)
        except (InputError, JobFailedError) as error:
            _one_line(error)
            refused += 1
            continue
        accepted += 1
        assert _inside(box, operator), (name, box, operator, file_box)
        sent, stopped = streamed_setpoints(plan.trajectory, firefly, box)
        assert stopped is None and unsafe(sent, firefly, operator) == [], name
    assert accepted and refused


def test_no_box_anywhere_is_bad_input(tmp_path, bases, firefly):
    doc = dict(bases[1], box=None)
    path = tmp_path / "nobox.json"
    path.write_text(json.dumps(doc))
    vehicle = tmp_path / "unboxed.toml"
    vehicle.write_text(vehicle_to_toml(replace(firefly, box=None)))
    with pytest.raises(InputError, match="no flight box from the operator; give --box"):
        load_plan(path, vehicle, None)


def test_an_excursion_between_samples_is_found(firefly):
    """A spike of 0.5 ms inside one segment (between 1 kHz samples) is still found."""
    traj = excitation_trajectory(ExcitationSpec(duration=12.0))
    limits = flight_limits(firefly, BOX)
    assert check_trajectory(traj, limits) == []
    pc = traj.position_coeffs.copy()
    # Add a narrow bump (tau (T - tau))^k, zero value and derivatives at both ends.
    i, T = 3, float(traj.durations[3])
    bump = np.polynomial.polynomial.polypow([0.0, T, -1.0], 4)  # degree 8 < 10
    pc[i, 2, : bump.size] += 3.0 * bump / np.max(np.polyval(bump[::-1],
                                                            np.linspace(0, T, 101)))
    spiked = type(traj)(traj.durations, pc, traj.yaw_coeffs)
    (reason,) = check_trajectory(spiked, limits)
    assert reason.startswith("z = ") and "outside the box" in reason


def test_guard_blocks_every_unsafe_setpoint(firefly):
    """The last line of defence on single setpoints: box, speed, thrust, yaw rate, NaN."""
    limits = flight_limits(firefly, BOX)
    good = Setpoint((0.0, 0.0, 1.5), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0), 0.3, 1.0)
    assert limits.refusal(good) is None
    bad = [Setpoint((500.0, 0.0, 1.5)), Setpoint((0.0, 0.0, 1.5), (23.0, 0.0, 0.0)),
           Setpoint((0.0, 0.0, 1.5), acceleration=(3094.0, 0.0, 0.0)),
           Setpoint((0.0, 0.0, 1.5), yaw_rate=500.0), Setpoint((float("nan"), 0.0, 1.5)),
           Setpoint((0.0, 0.0, 1.5), acceleration=(0.0, 0.0, -9.81)),
           Setpoint((0.0, 0.0, 3.0))]
    for sp in bad:
        reason = limits.refusal(sp)
        assert reason is not None and reason.startswith("unsafe setpoint not sent: "), sp
    # The climb from the ground runs in the column under the box.
    climb = SmoothMove.between(np.array([0.0, 0.0, 0.0]), 0.0, np.array([0.0, 0.0, 1.5]), 0.0)
    assert all(limits.refusal(climb.setpoint(t)) is None for t in np.linspace(0, 3, 31))


def test_guard_alone_stops_a_file_that_bypassed_the_check(bases, firefly):
    """A 5× compressed figure fed straight to the stream: without limits it would send
    unsafe setpoints; with them it sends none and stops in one line."""
    doc = scale_time(json.loads(json.dumps(bases[1])), 5.0)
    trajectory = parse_trajectory(doc, "compressed").trajectory
    sent, stopped = streamed_setpoints(trajectory, firefly, BOX, limits=False)
    assert unsafe(sent, firefly, BOX)  # the judge sees them
    sent, stopped = streamed_setpoints(trajectory, firefly, BOX)
    assert unsafe(sent, firefly, BOX) == []
    assert stopped is not None and stopped.startswith("unsafe setpoint not sent: ")


def _box_option(box=BOX) -> str:
    return ",".join(f"{b:g}" for b in box)


@pytest.mark.slow
def test_stream_refuses_a_bad_file_before_connecting(tmp_path, bases):
    """`mavsysid stream` with a file that widens its box and jumps 500 m: exit 3 in one
    line, no flight directory, nothing listening needed."""
    doc = MUTATIONS["jump"](json.loads(json.dumps(bases[1])), np.random.default_rng(5))
    path = tmp_path / "jump.json"
    path.write_text(json.dumps(doc))
    result = run_stream(path, "--connect", f"udp:127.0.0.1:{free_udp_port()}", "--box",
                        _box_option(), "--vehicle", "firefly", "--log-dir",
                        str(tmp_path / "logs"), cwd=tmp_path, timeout=120)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 3, result.stderr
    assert len(lines) == 1 and "flight refused: the trajectory leaves the box" in lines[0]
    assert not (tmp_path / "logs").exists()


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_accepted_mutated_file_flies_with_no_unsafe_setpoint(tmp_path, bases, firefly):
    """A slowed-down figure with a widened box in the file flies against the simulated
    vehicle; every setpoint in the tlog is inside --box and within the limits."""
    doc = scale_time(json.loads(json.dumps(bases[0])), 0.8)
    doc["box"] = [-500.0, -500.0, -500.0, 500.0, 500.0, 500.0]
    path = tmp_path / "slow.json"
    path.write_text(json.dumps(doc))
    port = free_udp_port()
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    "4"):
        result = run_stream(path, "--connect", f"udp:127.0.0.1:{port}", "--speedup", "4",
                            "--box", _box_option(), "--vehicle", "firefly", "--log-dir",
                            str(tmp_path / "logs"), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    sent = [SentSetpoint(ned_to_enu(np.array([m.x, m.y, m.z])),
                         ned_to_enu(np.array([m.vx, m.vy, m.vz])),
                         ned_to_enu(np.array([m.afx, m.afy, m.afz])),
                         float(yaw_rate_ned_to_enu(m.yaw_rate)))
            for _, m in read_tlog(flight_dir(tmp_path / "logs") / "flight.tlog")
            if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and m.get_srcSystem() == 255]
    assert len(sent) > 400
    assert unsafe(sent, firefly, BOX) == []


@pytest.mark.parametrize("text", ["[" * 100000 + "]" * 100000, '{"format": ' + "9" * 5000 + "}",
                                  '{"format": "mavsysid-trajectory", "format_version": 1, '
                                  '"kind": "x", "segments": [{"duration": 1e308, "position": '
                                  '[[0], [0], [0]], "yaw": [0]}, {"duration": 1e308, '
                                  '"position": [[0], [0], [0]], "yaw": [0]}], "duration": '
                                  + "1" * 400 + "}"])
def test_malformed_files_are_one_line_input_errors(tmp_path, text):
    """Deep nesting, a 5000-digit number, overflowing durations: InputError, no traceback."""
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_trajectory(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


@pytest.mark.parametrize(("table", "fragment"), [
    ("box = [-1.0, -1.0, 0.5, 1.0, 1.0]", "[flight].box: [x_min"),
    ("box = [1.0, -1.0, 0.5, -1.0, 1.0, 2.5]", "each min below its max"),
    ("box = [-1.0, -1.0, 0.5, 1.0, 1.0, \"2.5\"]", "[flight].box: a number (m)"),
    ("margin = 1.0", "[flight]: a table with only box")])
def test_vehicle_flight_box_is_validated(tmp_path, firefly, table, fragment):
    """The vehicle's optional [flight] box: six numbers, each min below its max; it
    survives a write and read back."""
    path = tmp_path / "v.toml"
    path.write_text(vehicle_to_toml(replace(firefly, box=None)) + f"\n[flight]\n{table}\n")
    with pytest.raises(InputError, match=re.escape(fragment)):
        load_vehicle(path)
    path.write_text(vehicle_to_toml(replace(firefly, box=None))
                    + "\n[flight]\nbox = [-1, -1, 0.5, 1, 1, 2.5]\n")
    boxed = load_vehicle(path)
    assert boxed.box == (-1.0, -1.0, 0.5, 1.0, 1.0, 2.5)
    path.write_text(vehicle_to_toml(boxed))
    assert load_vehicle(path).box == boxed.box
