"""Tests of ``mavsysid evaluate``: records, resumption, executors and the paper's table."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mavsysid.experiments.evaluate_job import make_specs, run_evaluation
from mavsysid.experiments.evaluation import load_records, median_convergence_time, summarise
from mavsysid.experiments.evaluation_intervals import (
    headline_intervals,
    off_path_flights,
    saturating_flights,
)
from mavsysid.experiments.experiment import draw_prior, run_experiment
from mavsysid.vehicle.config import load_vehicle

from mavsysid.cli import main

#: Small, sample-budgeted experiments: the records depend only on the seeds.
FAST = {"budget": 15.0, "samples": 300, "refine_steps": 30}


@pytest.fixture(scope="module")
def two_experiments(tmp_path_factory) -> Path:
    """An evaluation folder with two finished experiments."""
    out = tmp_path_factory.mktemp("evaluation")
    run_evaluation(out, make_specs(2, **FAST), png=True)
    return out


def test_prior_draw_is_within_50_percent_and_seeded():
    """The unknown parameters are drawn within ±50 % of the truth, the same for a seed."""
    truth = load_vehicle("firefly").theta
    draws = np.array([draw_prior(load_vehicle("firefly"), s) for s in range(50)])
    assert np.all(np.abs(draws / truth - 1.0) <= 0.5)
    assert np.array_equal(draws[3], draw_prior(load_vehicle("firefly"), 3))
    assert np.ptp(draws[:, 0] / truth[0]) > 0.5, "the draws spread over the range"


@pytest.mark.slow
def test_record_holds_both_planners_with_consistent_figures(two_experiments):
    """Each record has a DOPT and a RAND flight with D-opt, σ, errors and a history."""
    records = load_records(two_experiments)
    assert [r["spec"]["index"] for r in records] == [0, 1]
    for record in records:
        assert [f["kind"] for f in record["flights"]] == ["dopt", "random"]
        truth = np.array(record["truth"])
        for f in record["flights"]:
            cov = np.array(f["covariance"])
            assert f["reached_dopt"] == pytest.approx(np.linalg.det(cov) ** (1 / 6), rel=1e-6)
            assert np.allclose(f["relative_sigma"], np.sqrt(np.diag(cov)) / truth)
            assert np.allclose(f["relative_error"], np.array(f["estimate"]) / truth - 1.0)
            hist = np.array(f["history"]["theta"])
            assert hist.shape == (len(f["history"]["t"]), 6)
            assert np.allclose(hist[0], record["prior"], rtol=0.05), "history starts at prior"
            # Data efficiency: every σ_j/θ_j ≤ 1 % within the flight, or None.
            seconds = f["time_to_relative_sigma"]
            assert (seconds is None) == (max(f["relative_sigma"]) > 0.01)
            assert seconds is None or 0.0 <= seconds <= f["flight_time"] + 0.1


@pytest.mark.slow
def test_csv_has_a_row_per_flight_matching_the_records(two_experiments):
    """runs.csv has one row per flight whose numbers equal the stored records."""
    with (two_experiments / "runs.csv").open() as f:
        rows = list(csv.DictReader(f))
    records = load_records(two_experiments)
    assert len(rows) == 4
    for row in rows:
        flight = next(fl for fl in records[int(row["experiment"])]["flights"]
                      if fl["kind"] == row["kind"])
        assert float(row["reached_dopt"]) == flight["reached_dopt"]
        assert float(row["relative_error_j_z"]) == flight["relative_error"][5]
        assert float(row["saturated_fraction"]) == flight["saturated_fraction"]
        assert 0.0 <= flight["saturated_fraction"] <= 1.0
        assert 0.0 < float(row["tracking_rms"]) == flight["tracking_rms"]


@pytest.mark.slow
def test_table_and_plots_are_written(two_experiments):
    """table.md has the paper's rows (CONV TIME per parameter, DOPT); PNGs are real PNGs."""
    table = (two_experiments / "table.md").read_text()
    for name in ("c_T", "c_D", "c_M", "j_x", "j_y", "j_z", "DOPT", "DOPT-COV", "RAND"):
        assert name in table
    for png in ("convergence.png", "error_vs_sigma.png"):
        assert (two_experiments / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_table_notes_give_the_headline_intervals_and_saturating_flights(two_experiments):
    """Under the table: the D-opt ratio of the table's medians with its bootstrap interval,
    and the saturating flights counted from the records."""
    records = load_records(two_experiments)
    h = headline_intervals(records)
    summary = summarise(records)
    assert h.dopt_ratio == pytest.approx(summary.median_dopt["random"]
                                         / summary.median_dopt["dopt"])
    table = (two_experiments / "table.md").read_text()
    assert (f"random / planned {h.dopt_ratio:.2f} (95 % paired bootstrap interval over the "
            f"2 experiments {h.dopt_ratio_interval[0]:.2f}–{h.dopt_ratio_interval[1]:.2f}; "
            "paper: 4.4)"
            in table)
    saturating = saturating_flights(records)
    assert saturating.keys() == {"dopt", "random"}
    assert (f"planned {saturating['dopt'][0]} of 2, random {saturating['random'][0]} of 2."
            in table)
    off_path = off_path_flights(records)
    assert (f"than 0.5 m RMS (the true vehicle could not fly the plan): planned "
            f"{off_path['dopt'][0]} of 2, random {off_path['random'][0]} of 2." in table)


@pytest.mark.slow
def test_command_prints_the_table_and_its_notes(two_experiments, capsys):
    """A rerun over finished records prints the table and the very notes of table.md."""
    code = main(["evaluate", "--n", "2", "--budget", "15", "--samples", str(FAST["samples"]),
                 "--refine-steps", "30", "--out", str(two_experiments), "--no-png"])
    out = capsys.readouterr().out
    table = (two_experiments / "table.md").read_text()
    notes = table.split("simulated experiments.\n", 1)[1].strip().split("\n\n")
    assert code == 0 and len(notes) == 3
    assert out.startswith(f"2 experiments in {two_experiments} (0 run now, 2 reused).\n")
    assert table.split("\n\n")[0] in out
    assert "\n\n".join(notes) in out


@pytest.mark.parametrize(("ratios", "expected"), [
    ([[0.5, 0.9, 0.97, 1.0, 1.02]], 0.2),     # enters the band at t = 0.2 and stays
    ([[0.5, 1.0, 1.2, 1.0, 1.01]], 0.3),      # leaves it again once: the later entry counts
    ([[1.0, 1.0, 1.0, 1.0, 0.9]], np.nan),    # ends outside the band
    ([[0.5, 1.0, 1.0, 1.0, 1.0], [0.5, 0.5, 0.5, 1.0, 1.0], [2.0, 2.0, 1.0, 1.0, 1.0]], 0.1),
])
def test_median_convergence_time(ratios, expected):
    """Convergence is when the median over experiments enters 5 % and stays there."""
    r = np.repeat(np.array(ratios, dtype=float)[:, :, None], 6, axis=2)
    t = np.arange(5) * 0.1
    got = median_convergence_time(t, r)
    assert np.allclose(got, expected, equal_nan=True)


@pytest.mark.slow
def test_flight_controller_is_tuned_to_the_truth_unless_asked_for_the_prior():
    """The same plans; tuned to the truth (the default) the flights track within 1 cm, tuned
    to the ±50 % guess they leave the plan (thrust and inertia mis-modelled)."""
    truth_spec, = make_specs(1, **FAST)
    prior_spec, = make_specs(1, controller_model="prior", **FAST)
    assert truth_spec.controller_model == "truth" and truth_spec.key() != prior_spec.key()
    tuned, guessed = run_experiment(truth_spec), run_experiment(prior_spec)
    for a, b in zip(tuned["flights"], guessed["flights"], strict=True):
        assert a["predicted_dopt"] == b["predicted_dopt"], "the planner does not change"
        assert a["saturated_fraction"] == 0.0
        assert a["tracking_rms"] < 0.01
        assert b["tracking_rms"] > 3.0 * a["tracking_rms"]


@pytest.mark.slow
def test_summary_of_records_uses_the_last_iteration(tmp_path):
    """With iterations, σ shrinks from one iteration to the next and the summary uses the last."""
    record = run_experiment(make_specs(1, iterations=2, **FAST)[0])
    for kind in ("dopt", "random"):
        first, second = (f for f in record["flights"] if f["kind"] == kind)
        assert second["iteration"] == 2
        assert second["reached_dopt"] < first["reached_dopt"]
    summary = summarise([record])
    assert summary.median_dopt["dopt"] == record["flights"][1]["reached_dopt"]


@pytest.mark.slow
def test_rerun_reuses_finished_experiments(two_experiments, tmp_path):
    """A second run with more experiments computes only the new ones; old records stay."""
    out = tmp_path / "ev"
    (out / "runs").mkdir(parents=True)
    for p in (two_experiments / "runs").glob("*.json"):
        (out / "runs" / p.name).write_bytes(p.read_bytes())
    before = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")}
    run = run_evaluation(out, make_specs(3, **FAST), png=False)
    assert run.ran == 1
    assert {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("0000.json")} == \
        {"0000.json": before["0000.json"]}
    assert len(load_records(out)) == 3


@pytest.mark.slow
def test_other_settings_in_the_folder_are_refused(two_experiments, capsys):
    """Resuming with other settings is refused with one line, exit 2."""
    code = main(["evaluate", "--n", "2", "--samples", "99", "--budget", "15",
                 "--out", str(two_experiments), "--no-png"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "other settings" in err


@pytest.mark.parametrize(("argv", "fragment"), [
    (["--n", "0"], "--n 0"),
    (["--iterations", "0"], "--iterations 0"),
    (["--vehicle", "nosuch"], "nosuch"),
    (["--executor", "dask"], "--scheduler"),
    (["--workers", "0"], "--workers 0"),
    (["--rotor-headroom", "0.5"], "--rotor-headroom 0.5"),
    (["--controller-model", "guess"], "--controller-model 'guess'"),
])
def test_bad_input_exits_2_with_one_line(argv, fragment, tmp_path, capsys):
    """Bad options give exit code 2 and one line naming the problem."""
    code = main(["evaluate", "--samples", "10", "--out", str(tmp_path / "o"), *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and fragment in err


@pytest.mark.slow
def test_interrupted_evaluation_resumes_with_only_unfinished(tmp_path):
    """Ctrl-C after the first experiment keeps it; the rerun computes only the others."""
    out = tmp_path / "ev"
    argv = [sys.executable, "-m", "mavsysid", "evaluate", "--n", "3", "--samples",
            str(FAST["samples"]), "--budget", str(FAST["budget"]), "--refine-steps",
            str(FAST["refine_steps"]), "--out", str(out), "--no-png"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    # A shell's background job inherits SIGINT ignored; Ctrl-C is what is tested.
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # A wait, not a bound: on a busy machine the first experiment can take many minutes.
    deadline = time.monotonic() + 1200
    while not (out / "runs" / "0000.json").exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    assert proc.wait(60) == 130
    finished = sorted(p.name for p in (out / "runs").glob("*.json"))
    assert 1 <= len(finished) < 3
    kept = {name: (out / "runs" / name).stat().st_mtime_ns for name in finished}
    run = run_evaluation(out, make_specs(3, **FAST), png=False)
    assert run.ran == 3 - len(finished)
    assert {n: (out / "runs" / n).stat().st_mtime_ns for n in finished} == kept


@pytest.mark.slow
def test_dask_cluster_gives_the_same_csv_as_local(tmp_path):
    """4 experiments on a 2-worker LocalCluster (loopback) give the local executor's CSV."""
    distributed = pytest.importorskip("distributed")
    specs = make_specs(4, **FAST)
    run_evaluation(tmp_path / "local", specs, png=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1",
                                  dashboard_address=None, processes=True) as cluster:
        run_evaluation(tmp_path / "dask", specs, executor="dask",
                       scheduler=cluster.scheduler_address, png=False)
    local = (tmp_path / "local" / "runs.csv").read_text()
    assert local.count("\n") == 9
    assert (tmp_path / "dask" / "runs.csv").read_text() == local
    assert json.loads((tmp_path / "dask" / "runs" / "0003.json").read_text())["spec"]["index"] == 3
