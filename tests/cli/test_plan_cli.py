"""Tests of ``mavsysid plan``: validation, outputs, exit codes and determinism."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from mavsysid.formats.trajectory_file import read_trajectory
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle, save_vehicle

from mavsysid.cli import main
from mavsysid.errors import JobFailedError
from tests.support.fake_planner import install_fake_planner

HEADER = "t,x,y,z,vx,vy,vz,ax,ay,az,yaw,yaw_rate"


@pytest.fixture
def fake_planner(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, PlannerSettings]]:
    """Stand-ins for the planner's rrbt.plan and baseline.plan_random; records the calls."""
    return install_fake_planner(monkeypatch)


def _vehicle_with(tmp_path: Path, **limits: float) -> str:
    config = load_vehicle("firefly")
    path = tmp_path / "changed.toml"
    save_vehicle(replace(config, limits=replace(config.limits, **limits)), path)
    return str(path)


BAD_OPTIONS = {
    "box with 3 numbers": (["--box", "1,2,3"], "--box"),
    "box with a word": (["--box", "-2,-2,0.5,2,2,high"], "--box"),
    "box min above max": (["--box", "2,-2,0.5,-2,2,2.5"], "x_min"),
    "box too small": (["--box", "-2,-2,1,2,2,1.3"], "z side"),
    "budget 0": (["--budget", "0"], "--budget"),
    "negative budget": (["--budget", "-5"], "--budget"),
    "time 0 without samples": (["--time", "0"], "--time"),
    "samples 0": (["--samples", "0"], "--samples"),
    "start at the wall": (["--start", "1.95,0,1.5,0"], "--start"),
    "start with 2 numbers": (["--start", "0,0"], "--start"),
    "negative seed": (["--seed", "-1"], "--seed"),
    "unknown vehicle": (["--vehicle", "fireflyy"], "did you mean firefly"),
    "negative rotor headroom": (["--rotor-headroom", "-0.1"], "--rotor-headroom"),
    "rotor headroom without hover": (["--rotor-headroom", "0.45"], "hover speed"),
}


@pytest.mark.parametrize("options", BAD_OPTIONS.values(), ids=BAD_OPTIONS.keys())
def test_bad_request_exits_2_with_one_line(options, tmp_path, monkeypatch, capsys,
                                           fake_planner):
    """Each impossible request: exit 2, one stderr line naming the option, nothing planned."""
    argv, fragment = options
    monkeypatch.chdir(tmp_path)
    assert main(["plan", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mavsysid plan: error: ")
    assert fragment in err
    assert not fake_planner and not any(tmp_path.iterdir())


@pytest.mark.parametrize(("limits", "key"), [
    ({"thrust_min_ratio": 1.2}, "thrust_min_ratio"),
    ({"thrust_max_ratio": 0.9, "thrust_min_ratio": 0.5}, "thrust_max_ratio"),
    ({"rotor_speed_min": 600.0}, "rotor_speed_min"),
])
def test_limits_without_hover_exit_2(limits, key, tmp_path, monkeypatch, capsys, fake_planner):
    """T_min > m g, T_max < m g or an idle speed lifting more than m g: exit 2, one line."""
    vehicle = _vehicle_with(tmp_path, **limits)
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "--vehicle", vehicle]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "changed.toml" in err and key in err
    assert not fake_planner and sorted(p.name for p in tmp_path.iterdir()) == ["changed.toml"]


def test_output_directory_is_refused_before_planning(tmp_path, capsys, fake_planner):
    """-o naming a directory is exit 2 before any planning time is spent."""
    assert main(["plan", "-o", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err and not fake_planner


def test_plan_writes_files_and_summary(tmp_path, capsys, fake_planner):
    """Exit 0; JSON, CSV and RRD written; summary names D-opt, each σ and the outputs."""
    out, csv, rrd = tmp_path / "calib.json", tmp_path / "calib.csv", tmp_path / "calib.rrd"
    code = main(["plan", "--box", "-3,-3,0.5,3,3,2.5", "--budget", "12", "--seed", "7",
                 "--samples", "40", "-o", str(out), "--csv", str(csv), "--rrd", str(rrd)])
    text = capsys.readouterr().out
    assert code == 0
    ((kind, settings),) = fake_planner
    assert kind == "dopt" and settings.box == (-3.0, -3.0, 0.5, 3.0, 3.0, 2.5)
    assert (settings.seed, settings.max_samples, settings.budget) == (7, 40, 12.0)
    assert math.isinf(settings.planning_time), "--samples alone: no wall-clock limit"
    assert read_trajectory(out).kind == "dopt"
    assert csv.read_text().splitlines()[0] == HEADER
    assert rrd.stat().st_size > 1000
    assert "D-opt" in text and all(name in text for name in PARAMETER_NAMES)
    assert "40 samples, 12 vertices, 30 edges, 50 beliefs" in text
    assert str(out) in text and str(csv) in text and str(rrd) in text


def test_quiet_prints_only_the_trajectory_file(tmp_path, capsys, fake_planner):
    """-q prints the trajectory file's path alone, so scripts can capture it."""
    out = tmp_path / "t.json"
    assert main(["-q", "plan", "-o", str(out)]) == 0
    assert capsys.readouterr().out == f"{out}\n"
    assert fake_planner[0][1].planning_time == 30.0


def test_short_flight_warns_even_when_quiet(tmp_path, monkeypatch, capsys, fake_planner):
    """A plan's shortfall note reaches stderr as one warning line, even with -q."""
    rrbt = sys.modules["mavsysid.planner.rrbt"]
    made = rrbt.plan
    note = "a 12.0 s flight of the 30 s budget (40 %): the search stopped; try --time 60"
    monkeypatch.setattr(rrbt, "plan", lambda *a, **k: replace(made(*a, **k), shortfall=note))
    out = tmp_path / "t.json"
    assert main(["-q", "plan", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.out == f"{out}\n"
    assert captured.err == f"mavsysid plan: warning: {note}\n"
    assert json.loads(out.read_text())["planner"]["shortfall"] == note


def test_random_uses_the_baseline(tmp_path, fake_planner):
    """--random runs the paper's random baseline and says so in the file."""
    out = tmp_path / "r.json"
    assert main(["plan", "--random", "-o", str(out)]) == 0
    assert fake_planner[0][0] == "random" and read_trajectory(out).kind == "random"


def test_no_feasible_plan_exits_3_and_writes_nothing(tmp_path, monkeypatch, capsys,
                                                      fake_planner):
    """A planner failure is exit 3 with one line, and no file is written."""
    def fail(config, settings, progress=None):
        raise JobFailedError("no feasible trajectory found in 2.0 s of planning (40 samples, "
                             "1 vertices, 0 edges)")

    monkeypatch.setattr(sys.modules["mavsysid.planner.rrbt"], "plan", fail)
    assert main(["plan", "-o", str(tmp_path / "t.json"), "--csv", str(tmp_path / "t.csv")]) == 3
    lines = capsys.readouterr().err.splitlines()
    # The status line of the search, then the failure in one line.
    assert lines[0].startswith("mavsysid plan: planning a 30 s flight for firefly")
    assert len(lines) == 2 and "no feasible trajectory found" in lines[1]
    assert not any(tmp_path.iterdir())


# --- with the real planner -------------------------------------------------------------


def _real_plan(tmp_path: Path, name: str, *extra: str) -> Path:
    pytest.importorskip("mavsysid.planner.rrbt")
    out = tmp_path / f"{name}.json"
    # 120 samples: with seed 1 the planner connects its first vertex only after ~60.
    code = main(["plan", "--vehicle", "firefly", "--samples", "120", "--time", "60",
                 "--seed", "1", "--refine-steps", "300", "-o", str(out), *extra])
    assert code == 0
    return out


def test_real_plan_writes_readable_files(tmp_path, capsys):
    """A short real plan exits 0 and writes a JSON read_trajectory reads and the CSV."""
    csv = tmp_path / "a.csv"
    out = _real_plan(tmp_path, "a", "--csv", str(csv))
    read = read_trajectory(out)
    assert read.kind == "dopt" and read.predicted_dopt is not None and read.predicted_dopt > 0
    assert read.trajectory.duration <= 30.0 + 1e-9
    assert csv.read_text().splitlines()[0] == HEADER
    assert "D-opt" in capsys.readouterr().out


def test_real_plan_is_deterministic(tmp_path):
    """Two runs with the same seed and --samples give identical trajectories and D-opt."""
    a = json.loads(_real_plan(tmp_path, "a").read_text())
    b = json.loads(_real_plan(tmp_path, "b").read_text())
    assert a["segments"] == b["segments"]
    assert a["predicted_dopt"] == b["predicted_dopt"]


def test_noise_from_plans_at_the_noise_the_estimator_met(tmp_path, capsys, fake_planner,
                                                          monkeypatch):
    """--noise-from: the planner's model carries the flights' pose σ and densities (the
    median over several), its measurement rate the pose's rate; the summary says what each
    σ is expected to give."""
    met = {"position_m": 0.05, "attitude_rad": 0.0175, "pose_rate_hz": 30.0,
           "force_density": 0.3, "moment_density": 0.004}
    (tmp_path / "estimate.json").write_text(json.dumps({"noise_met": met}))
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"noise_met": {**met, "force_density": 0.5}}))
    third = tmp_path / "third.json"
    third.write_text(json.dumps({"noise_met": {**met, "force_density": 0.2}}))
    rrbt = sys.modules["mavsysid.planner.rrbt"]
    configs = []
    made = rrbt.plan
    monkeypatch.setattr(rrbt, "plan", lambda config, *a, **k: configs.append(config)
                        or made(config, *a, **k))
    out = tmp_path / "t.json"
    assert main(["plan", "--noise-from", str(tmp_path), str(other), str(third), "--samples",
                 "40", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    (noise,) = (c.noise for c in configs)
    assert (noise.position_sigma, noise.attitude_sigma) == (0.05, 0.0175)
    assert (noise.force_density, noise.moment_density) == (0.3, 0.004)
    assert fake_planner[0][1].measurement_rate == 30.0
    assert "planning for the noise the estimator met" in captured.err and "(median)" in captured.err
    assert "expected" in captured.out and "determined" in captured.out


def test_noise_from_without_an_estimate_exits_2_before_planning(tmp_path, capsys, fake_planner):
    assert main(["plan", "--noise-from", str(tmp_path), "-o", str(tmp_path / "t.json")]) == 2
    err = capsys.readouterr().err
    assert "no such estimate" in err and len(err.strip().splitlines()) == 1
    assert not fake_planner


def test_noise_from_flights_that_set_parameters_aside_expects_it_again(tmp_path, capsys,
                                                                      fake_planner):
    """Parameters set aside on most --noise-from flights are expected set aside again."""
    met = {"position_m": 0.05, "attitude_rad": 0.0175, "pose_rate_hz": 50.0,
           "force_density": 0.3, "moment_density": 0.004}
    resolved = {n: {"relative_sigma": 0.01} for n in PARAMETER_NAMES}
    aside = {n: {"status": "not determined by this flight" if n in ("c_M", "j_z")
                 else "determined"} for n in PARAMETER_NAMES}
    flights = []
    for i in range(3):
        document = {"noise_met": met, "filter": resolved,
                    "parameters": aside if i < 2 else {}}
        flights.append(tmp_path / f"e{i}.json")
        flights[-1].write_text(json.dumps(document))
    out = tmp_path / "t.json"
    assert main(["plan", "--noise-from", *map(str, flights), "--samples", "40", "-o",
                 str(out)]) == 0
    text = capsys.readouterr().out
    rows = {line.split()[0]: line for line in text.splitlines() if line.startswith("    ")}
    assert rows["c_M"].endswith("set aside before") and rows["j_z"].endswith("set aside before")
    assert rows["c_T"].endswith("determined") and "set aside" not in rows["c_T"]
    assert "set aside  c_M, j_z:" in text
