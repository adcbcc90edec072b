"""Tests of ``mavsysid estimate``: outputs, and one-line errors for bad logs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mavsysid.formats.poselog import read_pose_log, write_pose_log
from mavsysid.pipeline.simulate import run_offline_flight
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

from mavsysid.cli import main


@pytest.fixture(scope="module")
def flight_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 12 s simulated Firefly flight."""
    logs = tmp_path_factory.mktemp("logs")
    return run_offline_flight("firefly", logs, "f", duration=12.0).directory


def test_estimate_writes_json_vehicle_and_recording(flight_dir, tmp_path, capsys):
    """Exit 0; the JSON has all six parameters with σ; the new config carries the estimates."""
    out, toml, rrd = tmp_path / "est.json", tmp_path / "new.toml", tmp_path / "est.rrd"
    code = main(["estimate", str(flight_dir / "pose.csv"), "--vehicle", "firefly", "-o", str(out),
                 "--update-vehicle", str(toml), "--rrd", str(rrd)])
    text = capsys.readouterr().out
    assert code == 0
    assert "Filter vs batch refinement" in text and "true" in text
    report = json.loads(out.read_text())
    values = np.array([report["parameters"][n]["value"] for n in PARAMETER_NAMES])
    sigmas = np.array([report["parameters"][n]["sigma"] for n in PARAMETER_NAMES])
    assert np.all(sigmas > 0.0)
    np.testing.assert_allclose(load_vehicle(toml).theta, values, rtol=1e-12)
    truth = load_vehicle("firefly").theta
    assert np.all(np.abs(values / truth - 1.0) < 0.05)
    assert rrd.stat().st_size > 1000


def _broken_copy(flight_dir: Path, tmp_path: Path, **change) -> Path:
    log = read_pose_log(flight_dir / "pose.csv")
    t, speeds = log.t, log.rotor_speeds
    if "speeds" in change:
        speeds = change["speeds"](speeds)
    if "duration" in change:
        keep = t <= change["duration"]
        t, speeds = t[keep], speeds[keep]
        log = type(log)(t, log.position[keep], log.quaternion[keep], speeds, {}, None)
    else:
        log = type(log)(t, log.position, log.quaternion, speeds, {}, None)
    path = tmp_path / "pose.csv"
    write_pose_log(path, log)
    return path


@pytest.mark.parametrize(("change", "vehicle", "fragment"), [
    ({"speeds": lambda n: n * 60 / (2 * np.pi)}, "firefly", "rpm"),
    ({"speeds": lambda n: n / 838.0}, "firefly", "normalised"),
    ({"duration": 1.5}, "firefly", "2 s"),
    ({}, "quad_x", "rotor"),
])
def test_bad_logs_exit_2_with_one_line(flight_dir, tmp_path, capsys, change, vehicle, fragment):
    """rpm or normalised speeds, < 2 s of data, a wrong rotor count: exit 2, one line."""
    path = _broken_copy(flight_dir, tmp_path, **change)
    code = main(["estimate", str(path), "--vehicle", vehicle])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert fragment in err and "pose.csv" in err


def test_missing_and_corrupt_logs_exit_2(tmp_path, capsys):
    """A missing file and a corrupt .tlog are one-line errors with exit code 2."""
    assert main(["estimate", str(tmp_path / "nope.csv")]) == 2
    (tmp_path / "bad.tlog").write_bytes(b"\x00\x01garbage" * 50)
    assert main(["estimate", str(tmp_path / "bad.tlog")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2 and "Traceback" not in err


def test_config_effects_are_fitted_reported_and_written_back(flight_dir, tmp_path, capsys):
    """A config's [effects.motor_lag]: fitted tau with σ in JSON and table and the new config."""
    from dataclasses import replace

    from mavsysid.vehicle.config import save_vehicle
    from mavsysid.vehicle.model_effects import MotorLag

    vehicle = tmp_path / "lagged.toml"
    save_vehicle(replace(load_vehicle("firefly"), effects=(MotorLag(tau=0.02),)), vehicle)
    out, toml = tmp_path / "est.json", tmp_path / "new.toml"
    code = main(["estimate", str(flight_dir / "pose.csv"), "--vehicle", str(vehicle),
                 "--no-refine", "-o", str(out), "--update-vehicle", str(toml)])
    text = capsys.readouterr().out
    assert code == 0 and "Model effects" in text and "motor_lag" in text
    (entry,) = json.loads(out.read_text())["effects"]
    tau = entry["parameters"]["tau"]
    assert entry["name"] == "motor_lag" and entry["fitted"] is True
    assert tau["sigma"] > 0.0 and tau["ci95"][0] < tau["value"] < tau["ci95"][1]
    # The log holds the actual speeds, so the extra lag found is small (≠ the 20 ms start).
    assert abs(tau["value"]) < 0.01
    (written,) = load_vehicle(toml).effects
    assert written == MotorLag(tau=tau["value"])
