"""Tests of the estimate report: convergence time, stdout table, estimate.json, new config."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.report.text import (
    format_table,
    result_to_json,
    software_version,
    updated_vehicle,
    write_estimate_json,
)
from mavsysid.estimation.results import (
    EstimationHistory,
    EstimationResult,
    ParameterEstimate,
    convergence_time,
)
from mavsysid.vehicle.config import (
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    VehicleConfig,
    load_vehicle,
    save_vehicle,
)

GOLDEN = Path(__file__).parent / "golden"
TRUE_THETA = np.array([8.54858e-6, 0.0176, 1.36777e-7, 0.0347563, 0.0458929, 0.0977])


def _estimate(rng: np.random.Generator, value: np.ndarray, rel_sigma: np.ndarray
              ) -> ParameterEstimate:
    """A ParameterEstimate with a random (positive definite) correlation."""
    a = rng.normal(size=(6, 6))
    cov = a @ a.T + 6.0 * np.eye(6)
    d = 1.0 / np.sqrt(np.diag(cov))
    sigma = rel_sigma * np.abs(value)
    return ParameterEstimate(value, (d[:, None] * cov * d) * np.outer(sigma, sigma))


def synthetic_result(*, truth: bool = True, refined: bool = True,
                     pose_source: str = "motion_capture", notes: tuple[str, ...] = (),
                     seed: int = 7, n: int = 201) -> EstimationResult:
    """A filter run that decays from the prior to a final estimate; c_D ends 8 % off."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 20.0, n)
    prior = TRUE_THETA * np.array([1.2, 0.7, 0.8, 1.15, 0.9, 1.1])
    final_error = np.array([0.002, 0.08, -0.01, -0.004, 0.003, 0.006])
    decay = np.exp(-t[:, None] / np.array([1.0, 6.0, 2.0, 1.5, 1.5, 3.0]))
    start = prior / TRUE_THETA - 1.0 - final_error
    theta = TRUE_THETA * (1.0 + final_error + start * decay
                          + 0.002 * rng.standard_normal((n, 6)))
    rel_sigma = np.array([0.004, 0.05, 0.01, 0.006, 0.006, 0.008])
    theta_sigma = TRUE_THETA * (rel_sigma + 0.3 * decay)
    theta[-1] = TRUE_THETA * (1.0 + final_error)
    quaternion = np.column_stack([np.ones(n), 0.05 * rng.standard_normal((n, 3))])
    quaternion /= np.linalg.norm(quaternion, axis=1, keepdims=True)
    position = np.column_stack([np.sin(0.5 * t), np.cos(0.3 * t), 1.0 + 0.1 * t])
    innovation = np.column_stack([5e-4 * rng.standard_normal((n, 3)),
                                  1.7e-3 * rng.standard_normal((n, 3))])
    history = EstimationHistory(t, theta, theta_sigma, position, quaternion, innovation,
                                rng.chisquare(6, n))
    position_sigma, attitude_sigma = ((0.0005, math.radians(0.1)) if pose_source ==
                                      "motion_capture" else (0.02, math.radians(1.0)))
    reference = TRUE_THETA if truth else theta[-1]
    filtered = _estimate(rng, theta[-1], rel_sigma)
    better = TRUE_THETA * (1.0 + 0.5 * final_error)
    return EstimationResult(
        prior=ParameterEstimate(prior, np.diag((0.3 * prior) ** 2)),
        filtered=filtered,
        refined=_estimate(rng, better, 0.7 * rel_sigma) if refined else None,
        history=history,
        convergence_time=convergence_time(t, theta, reference),
        true_theta=TRUE_THETA.copy() if truth else None,
        measurement_sigma=(position_sigma, attitude_sigma),
        pose_source=pose_source,
        notes=notes,
    )


def _converged_by_loop(t: np.ndarray, theta: np.ndarray, ref: np.ndarray, tol: float
                       ) -> np.ndarray:
    """Reference implementation: scan each parameter backwards from the end."""
    out = np.full(ref.size, np.nan)
    for j in range(ref.size):
        for i in range(t.size - 1, -1, -1):
            if not abs(theta[i, j] - ref[j]) <= tol * abs(ref[j]):
                break
            out[j] = t[i]
    return out


# --- convergence_time ------------------------------------------------------------------


@pytest.mark.parametrize(("series", "expected"), [
    ([1.5, 1.2, 1.04, 1.01, 1.0], 2.0),    # enters the band and stays
    ([1.0, 1.01, 1.2, 1.02, 1.03], 3.0),   # leaves once: counts from the last entry
    ([1.0, 1.0, 1.0, 1.0, 1.0], 0.0),      # inside from the first sample
    ([1.0, 1.0, 1.0, 1.0, 1.2], math.nan),  # last sample outside: never
    ([2.0, 2.0, 2.0, 2.0, 2.0], math.nan),  # never inside
    ([1.0, 1.0, math.nan, 1.0, 1.0], 3.0),  # a NaN estimate is outside
])
def test_convergence_time_cases(series, expected):
    """The first time after which the estimate stays within ±5 %, NaN if it never settles."""
    got = convergence_time(np.arange(5.0), np.array(series)[:, None], np.array([1.0]))
    np.testing.assert_equal(got, [expected])


def test_convergence_time_band_edges_are_inside():
    """A value exactly on the band's edge counts as inside (≤, not <)."""
    got = convergence_time(np.arange(4.0), np.array([[1.5], [1.25], [0.75], [1.0]]),
                           np.array([1.0]), tolerance=0.25)
    np.testing.assert_equal(got, [1.0])


def test_convergence_time_uses_magnitude_of_negative_reference():
    """A negative reference gets a band of ±tolerance·|reference|, not an empty one."""
    got = convergence_time(np.arange(3.0), np.array([[-2.0], [-1.04], [-0.97]]),
                           np.array([-1.0]))
    np.testing.assert_equal(got, [1.0])


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("tolerance", [0.01, 0.05, 0.2])
def test_convergence_time_matches_loop(seed, tolerance):
    """The vectorised result equals a per-parameter backward scan on random walks."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 10.0, 300))
    ref = rng.uniform(0.5, 2.0, 6) * rng.choice([-1.0, 1.0], 6)
    theta = ref * (1.0 + np.cumsum(rng.normal(0.0, 0.01, (300, 6)), axis=0)[::-1])
    np.testing.assert_array_equal(convergence_time(t, theta, ref, tolerance),
                                  _converged_by_loop(t, theta, ref, tolerance))


def test_convergence_time_of_no_samples_is_nan():
    """An empty history has converged nowhere."""
    assert np.isnan(convergence_time(np.empty(0), np.empty((0, 6)), np.ones(6))).all()


def test_convergence_time_rejects_mismatched_shapes():
    """theta must be (N, P) for t (N,) and reference (P,)."""
    with pytest.raises(ValueError, match="theta of shape"):
        convergence_time(np.arange(4.0), np.ones((5, 6)), np.ones(6))


# --- table -----------------------------------------------------------------------------


@pytest.mark.parametrize(("golden", "kwargs"), [
    ("table_truth_refined.txt",
     {"truth": True, "refined": True, "notes": ("3 rows with NaN dropped",)}),
    ("table_autopilot.txt",
     {"truth": False, "refined": False, "pose_source": "autopilot",
      "notes": ("pose taken from LOCAL_POSITION_NED and ATTITUDE_QUATERNION",
                "rotor speeds stamped on receipt")}),
])
def test_table_matches_golden(golden, kwargs, firefly):
    """The printed table for a fixed synthetic result matches its golden file."""
    text = format_table(synthetic_result(**kwargs), firefly, "logs/synthetic/pose.csv")
    assert text == (GOLDEN / golden).read_text(encoding="utf-8")


@pytest.mark.parametrize("truth", [True, False])
def test_table_shows_truth_columns_only_with_truth(truth, firefly):
    """'true' and 'error %' columns appear exactly when the result knows the truth."""
    text = format_table(synthetic_result(truth=truth), firefly, "x")
    assert ("error %" in text) is truth
    assert (" true " in text) is truth


@pytest.mark.parametrize("refined", [True, False])
def test_table_compares_filter_and_refined_only_when_refined(refined, firefly):
    """The filter-vs-refined block appears exactly when refinement ran."""
    text = format_table(synthetic_result(refined=refined), firefly, "x")
    assert ("Filter vs batch refinement" in text) is refined


@pytest.mark.parametrize("pose_source", ["motion_capture", "autopilot"])
def test_table_warns_about_autopilot_pose(pose_source, firefly):
    """Only an autopilot pose gets the 'filtered and lagged, less certain' explanation."""
    text = format_table(synthetic_result(pose_source=pose_source), firefly, "x")
    assert ("autopilot's own estimator" in text) is (pose_source == "autopilot")


def test_table_rows_hold_final_estimate_and_notes(firefly):
    """Each parameter's row shows the final (refined) value; notes and mass caveat follow."""
    result = synthetic_result(notes=("first", "second"))
    lines = format_table(result, firefly, "x").splitlines()
    for j, name in enumerate(PARAMETER_NAMES):
        row = next(line for line in lines if line.startswith(name + " "))
        assert f"{result.refined.value[j]:.3e}" in row
    assert "note: first" in lines and "note: second" in lines
    assert "taken as known" in lines[-2]


# --- JSON ------------------------------------------------------------------------------


@pytest.mark.parametrize("truth", [True, False])
@pytest.mark.parametrize("refined", [True, False])
def test_json_shape(truth, refined, firefly):
    """All six parameters in every block; truth keys only with truth; refined null if absent."""
    result = synthetic_result(truth=truth, refined=refined)
    doc = result_to_json(result, firefly, "logs/a/pose.csv")
    blocks = ["parameters", "filter", "prior"] + (["refined"] if refined else [])
    keys = {"value", "unit", "sigma", "relative_sigma", "convergence_time_s"}
    keys |= {"true_value", "error_relative"} if truth else set()
    for block in blocks:
        assert list(doc[block]) == list(PARAMETER_NAMES)
        assert all(set(entry) == keys for entry in doc[block].values())
    assert (doc["refined"] is None) is (not refined)
    assert doc["parameter_names"] == list(PARAMETER_NAMES)
    assert (doc["log"], doc["vehicle"]) == ("logs/a/pose.csv", "firefly")
    assert doc["software"] == {"name": "mavsysid", "version": software_version()}


def test_json_gives_each_parameters_unit(firefly):
    """Every block names each parameter's SI unit, the config's, and it survives the file."""
    result = synthetic_result()
    doc = json.loads(json.dumps(result_to_json(result, firefly, "x")))
    for block in ("parameters", "filter", "refined", "prior"):
        assert {n: doc[block][n]["unit"] for n in PARAMETER_NAMES} == PARAMETER_UNITS
    assert doc["parameters"]["c_T"]["unit"] == "N/(rad/s)²"
    assert doc["parameters"]["j_z"]["unit"] == "kg·m²"


def test_json_values_are_the_final_estimate(firefly):
    """'parameters' and 'covariance' are the refined estimate; 'filter' is the EKF's."""
    result = synthetic_result()
    doc = result_to_json(result, firefly, "x")
    np.testing.assert_array_equal([doc["parameters"][n]["value"] for n in PARAMETER_NAMES],
                                  result.refined.value)
    np.testing.assert_array_equal([doc["filter"][n]["sigma"] for n in PARAMETER_NAMES],
                                  result.filtered.sigma)
    np.testing.assert_array_equal(doc["covariance"], result.refined.covariance)
    c_t = doc["parameters"]["c_T"]
    assert c_t["error_relative"] == pytest.approx(
        (result.refined.value[0] - TRUE_THETA[0]) / TRUE_THETA[0])


def test_json_convergence_time_is_the_filters(firefly):
    """Convergence (null if never) is given with the final and filter estimates only."""
    result = synthetic_result()
    doc = result_to_json(result, firefly, "x")
    for block in ("parameters", "filter"):
        assert doc[block]["c_T"]["convergence_time_s"] == result.convergence_time[0] > 0.0
        assert doc[block]["c_D"]["convergence_time_s"] is None
    for block in ("refined", "prior"):
        assert all(e["convergence_time_s"] is None for e in doc[block].values())
    json.dumps(doc, allow_nan=False)


def test_zero_true_value_has_no_relative_error(firefly):
    """A true c_D of 0 (a simulation without rotor drag) gives n/a and null, not a crash."""
    result = dataclasses.replace(synthetic_result(), true_theta=TRUE_THETA * [1, 0, 1, 1, 1, 1])
    doc = result_to_json(result, firefly, "x")
    assert doc["parameters"]["c_D"]["error_relative"] is None
    assert doc["parameters"]["c_T"]["error_relative"] is not None
    json.dumps(doc, allow_nan=False)
    row = next(line for line in format_table(result, firefly, "x").splitlines()
               if line.startswith("c_D "))
    assert row.endswith("n/a")


def test_json_measurement_sigma_and_source(firefly):
    """The assumed noise is stored in SI (m, rad) with the pose source."""
    doc = result_to_json(synthetic_result(pose_source="autopilot"), firefly, "x")
    assert doc["pose_source"] == "autopilot"
    assert doc["measurement_sigma"] == {"position_m": 0.02,
                                        "attitude_rad": pytest.approx(math.radians(1.0))}


def test_write_estimate_json_round_trips(tmp_path, firefly):
    """The file holds result_to_json, in a new directory, with no temporary left behind."""
    path = tmp_path / "out" / "deeper" / "estimate.json"
    path.parent.mkdir(parents=True)
    path.write_text("old, longer content that must vanish entirely " * 100)
    result = synthetic_result()
    write_estimate_json(path, result, firefly, "logs/a/pose.csv")
    assert json.loads(path.read_text()) == result_to_json(result, firefly, "logs/a/pose.csv")
    assert os.listdir(path.parent) == ["estimate.json"]


def test_write_estimate_json_creates_directory(tmp_path, firefly):
    """A missing parent directory is created."""
    path = tmp_path / "new" / "estimate.json"
    write_estimate_json(path, synthetic_result(refined=False), firefly, "x")
    assert json.loads(path.read_text())["refined"] is None


# --- updated config --------------------------------------------------------------------


def test_updated_vehicle_takes_final_estimate(tmp_path, firefly: VehicleConfig):
    """The new config's nominal θ is the final estimate and survives save/load exactly."""
    result = synthetic_result()
    new = updated_vehicle(firefly, result)
    np.testing.assert_array_equal(new.theta, result.refined.value)
    assert (new.mass, new.rotors, new.limits) == (firefly.mass, firefly.rotors, firefly.limits)
    save_vehicle(new, tmp_path / "v.toml")
    np.testing.assert_array_equal(load_vehicle(tmp_path / "v.toml").theta, new.theta)
