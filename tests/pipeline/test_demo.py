"""Tests of the demo (`mavsysid.pipeline.demo`): plan, fly over MAVLink against the simulated
vehicle, estimate, diagnose."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mavsysid.formats.poselog import read_pose_log
from mavsysid.pipeline.demo import DemoSettings, run_demo
from mavsysid.pipeline.demo_flight import hidden_scale
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle
from rerun.chunk import RrdReader

from mavsysid.cli.demo import format_summary


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """One demo round with a short planning time."""
    logs = tmp_path_factory.mktemp("logs")
    return run_demo(DemoSettings(planning_time=4.0, logs=logs), progress=False, name="demo")


def test_hidden_truth_is_seeded_physical_and_differs_from_the_nominal():
    """The simulated vehicle's θ is hidden, seeded, within the spread and a valid inertia."""
    config = load_vehicle("firefly")
    scales = np.array([hidden_scale(config, s) for s in range(20)])
    assert np.array_equal(scales[4], hidden_scale(config, 4))
    assert np.all(np.abs(scales[:, 1:] - 1.0) <= 0.3) and np.all(np.abs(scales[:, 0] - 1) <= 0.05)
    assert np.all(np.abs(scales - 1.0).max(axis=1) > 0.05)
    j = config.theta[3:] * scales[:, 3:]
    assert np.all(j.max(axis=1) <= 1.25 * (j.sum(axis=1) - j.max(axis=1)))


@pytest.mark.slow
def test_demo_flies_the_plan_over_mavlink_and_estimates_within_its_sigma(demo_run):
    """The streamed flight is recorded; the estimate is within 4σ of the simulator's truth."""
    (round_,) = demo_run.rounds
    rows = read_pose_log(round_.flight_dir / "pose.csv")
    assert len(rows) > 7500, "250 Hz telemetry over a 30 s plan, the take-off and landing"
    assert round_.tracking_rms < 0.1
    error = (round_.estimate.value - demo_run.true_theta) / round_.estimate.sigma
    assert np.all(np.abs(error) < 4.0), error
    scale = demo_run.true_theta / demo_run.config.theta
    moved = np.abs(round_.estimate.value / demo_run.config.theta - 1.0)
    assert np.all(moved[np.abs(scale - 1.0) > 0.05] > 0.02), "the estimate left the prior"


@pytest.mark.slow
def test_demo_writes_the_estimate_and_the_truth(demo_run):
    """estimate.json holds the final θ with σ, the truth and each round's D-opt."""
    doc = json.loads((demo_run.directory / "estimate.json").read_text())
    assert set(doc["parameters"]) == set(PARAMETER_NAMES)
    assert np.allclose([doc["true_parameters"][n] for n in PARAMETER_NAMES],
                       demo_run.true_theta)
    (r,) = doc["rounds"]
    assert r["reached_dopt"] > 0.0 and r["predicted_dopt"] > 0.0


@pytest.mark.slow
def test_demo_writes_one_recording_of_every_stage(demo_run):
    """demo.rrd holds the plan, the estimate and the per-round D-opt."""
    entities = {chunk.entity_path for chunk in RrdReader(demo_run.files["recording"]).stream()}
    assert any(e.startswith("/planner/sigma/") for e in entities)
    assert any(e.startswith("/parameters/j_z/") for e in entities)
    assert any(e.startswith("/residual/") for e in entities), "the diagnosis is in it"
    assert "/rounds/dopt/reached" in entities


@pytest.mark.slow
def test_demo_diagnoses_a_faithful_model_as_such(demo_run):
    """Without a hidden effect the diagnosis finds no significant discrepancy, and says so."""
    assert demo_run.diagnosis is not None and not demo_run.diagnosis.effects
    doc = json.loads((demo_run.directory / "diagnosis.json").read_text())
    assert doc["effects"] == []
    assert "no significant discrepancy" in format_summary(demo_run)
