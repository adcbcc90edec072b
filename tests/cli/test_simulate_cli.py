"""Tests of ``mavsysid simulate`` with hidden effects and trajectory files."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle

from mavsysid.cli import main
from tests.support.trajectories import ground_descent, write_trajectory_json


@pytest.mark.parametrize(("spec", "detail"), [
    ("foo:x=1", "unknown effect 'foo'; expected one of body_drag, rotor_drag_linear, "
                "motor_lag, pose_delay, marker_offset, cog_offset, wind, thrust_drift, "
                "ground_effect, rotor_inertia, rotor_speed_lag"),
    ("motor_lag:tua=0.04", "unknown parameter 'tua'; expected one of tau"),
    ("wind:x=two", "'x=two' is not KEY=NUMBER"),
    ("wind:x", "'x' is not KEY=NUMBER"),
    ("wind:x=inf", "expected a finite number"),
])
def test_bad_hidden_effect_exits_2_with_one_line(tmp_path, capsys, spec, detail):
    """A bad --hidden-effect is exit 2, one line naming the spec and the problem."""
    code = main(["simulate", "--logs", str(tmp_path), "--hidden-effect", "wind:x=2",
                 "--hidden-effect", spec])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"mavsysid simulate: error: --hidden-effect {spec!r}: ")
    assert detail in err
    assert err.count("\n") == 1
    assert not any(tmp_path.iterdir())


def test_hidden_effects_combine_and_are_recorded(tmp_path, capsys):
    """Two --hidden-effect options: both in truth.effects; motor lag logs the commands."""
    code = main(["simulate", "--logs", str(tmp_path), "--name", "f", "--duration", "10",
                 "--no-noise", "--hidden-effect", "wind:x=2",
                 "--hidden-effect", "motor_lag:tau=0.04"])
    out = capsys.readouterr().out
    assert code == 0
    assert "hidden     Wind(x=2, y=0); MotorLag(tau=0.04)" in out
    meta = read_meta(tmp_path / "f" / "meta.json")
    assert [e["name"] for e in meta["truth"]["effects"]] == ["wind", "motor_lag"]
    assert all(e["hidden"] for e in meta["truth"]["effects"])
    assert meta["truth"]["motor_time_constant_s"] == 0.04
    k = load_vehicle("firefly").rotor_count
    pose = read_pose_log(tmp_path / "f" / "pose.csv", k)
    truth = read_pose_log(tmp_path / "f" / "truth.csv", k)
    commands = np.genfromtxt(tmp_path / "f" / "truth.csv", delimiter=",", names=True)
    for i in range(k):
        np.testing.assert_allclose(pose.rotor_speeds[:, i], commands[f"n_cmd{i + 1}"],
                                   atol=1e-3)
    assert np.abs(pose.rotor_speeds - truth.rotor_speeds).max() > 1.0


def test_trajectory_file_is_flown_near_the_ground(tmp_path, capsys):
    """--trajectory flies the file (here down to 0.1 m) with a hidden ground effect."""
    config = load_vehicle("firefly")
    path = write_trajectory_json(tmp_path / "descent.json", ground_descent(repeats=1), config,
                                 "descent")
    code = main(["simulate", "--logs", str(tmp_path), "--name", "f", "--trajectory", str(path),
                 "--hidden-effect", "ground_effect:rotor_radius=0.1"])
    out = capsys.readouterr().out
    assert code == 0
    assert f"flying the trajectory {path} (descent) (14.0 s)" in out
    meta = read_meta(tmp_path / "f" / "meta.json")
    assert meta["trajectory"]["kind"] == "descent"
    assert meta["trajectory"]["duration_s"] == pytest.approx(14.0)
    pose = read_pose_log(tmp_path / "f" / "pose.csv", config.rotor_count)
    assert pose.position[:, 2].min() == pytest.approx(0.1, abs=0.03)


@pytest.mark.parametrize(("args", "detail"), [
    (["--duration", "12"], "--duration: only for the built-in excitation"),
    ([], "not valid JSON"),
])
def test_bad_trajectory_use_exits_2(tmp_path, capsys, args, detail):
    """A broken trajectory file, or --duration with --trajectory, is exit 2 in one line."""
    path = tmp_path / "bad.json"
    path.write_text("{" if not args else "{}")
    code = main(["simulate", "--logs", str(tmp_path / "logs"), "--trajectory", str(path), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert detail in err and err.count("\n") == 1
    assert not (tmp_path / "logs").exists()
