"""Tests of the estimate job (`mavsysid.pipeline.estimate`): it refuses an impossible θ
before anything is written, and answers per parameter from the balance and the filter."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import mavsysid.estimation.answer as answer
import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import estimate_parameters
from mavsysid.estimation.report.text import result_to_json
from mavsysid.estimation.results import Z95, ParameterEstimate
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.pipeline import estimate as estimate_job
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle, vehicle_to_toml

from mavsysid.cli.main import main
from mavsysid.errors import JobFailedError

PRIOR = load_vehicle("quad_x").theta
PRIOR_SIGMA = 0.5 * PRIOR


def _stub_result(theta: np.ndarray) -> SimpleNamespace:
    final = SimpleNamespace(value=theta, sigma=0.05 * np.abs(theta))
    prior = SimpleNamespace(value=PRIOR, sigma=PRIOR_SIGMA)
    final.theta, prior.theta = final, prior  # θ alone: the paper's six
    return SimpleNamespace(final=final, prior=prior, equation_error=None, effects=())


@pytest.fixture
def stub_estimation(monkeypatch: pytest.MonkeyPatch) -> Callable[[np.ndarray], None]:
    """Replace reading and the filter by stubs returning a given θ."""

    def use(theta: np.ndarray) -> None:
        monkeypatch.setattr(estimate_job, "load_flight",
                            lambda log, config, **kw: SimpleNamespace(
                                source=str(log), rotor_count=0, duration=0.0, imu=None,
                                rotor_scale_sigma=0.0))
        monkeypatch.setattr(answer, "check_kinematics", lambda flight: None)
        monkeypatch.setattr(answer, "estimate_parameters",
                            lambda flight, config, settings=None, reference=None:
                            _stub_result(theta))

    return use


def test_run_estimate_returns_a_plausible_estimate(stub_estimation) -> None:
    stub_estimation(PRIOR * 1.3)
    run = estimate_job.run_estimate("flight.ulg", "quad_x")
    np.testing.assert_array_equal(run.result.final.value, PRIOR * 1.3)


def test_estimate_command_refuses_negative_c_M_without_writing(
    stub_estimation, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    theta = PRIOR.copy()
    theta[PARAMETER_NAMES.index("c_M")] = -5e-15
    stub_estimation(theta)
    out, toml = tmp_path / "estimate.json", tmp_path / "vehicle.toml"
    code = main(["estimate", "flight.ulg", "--vehicle", "quad_x", "-o", str(out),
                 "--update-vehicle", str(toml)])
    err = capsys.readouterr().err
    assert code == 3
    assert err.splitlines() == [err.strip()]
    assert err.startswith("mavsysid estimate: error: flight.ulg: c_M = -5e-15 ± ")
    assert not out.exists() and not toml.exists()


@pytest.fixture(scope="module")
def simulated_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 20 s simulated micro_quad excitation flight logged at 250 Hz (pose.csv), and a
    vehicle file beside it whose prior θ is 30–50 % off the truth (prior.toml)."""
    directory = tmp_path_factory.mktemp("flight")
    Simulator(load_vehicle("micro_quad"), settings=SimulationSettings(seed=2, log_rate=250.0)
              ).run(excitation_trajectory(ExcitationSpec(duration=20.0)), directory)
    config = load_vehicle("micro_quad")
    prior = config.with_parameters(config.theta * np.array([1.4, 0.6, 1.5, 0.65, 1.35, 1.5]))
    (directory / "prior.toml").write_text(vehicle_to_toml(prior), encoding="utf-8")
    return directory / "pose.csv"


def _filter_refuses(flight, config, settings=None, reference=None):
    raise JobFailedError(f"{flight.source}: the parameter filter diverged (test)")


def test_balance_answers_when_the_filter_cannot_follow(simulated_log: Path) -> None:
    """A filter that refuses is no refusal of the flight: the balance answers per parameter,
    with statuses, its held-out check, and the filter's refusal said in the notes and JSON."""
    run = estimate_job.run_estimate(simulated_log, simulated_log.parent / "prior.toml",
                                    filter_estimate=_filter_refuses)
    result = run.result
    assert result.filter_refusal is not None and "diverged (test)" in result.filter_refusal
    assert len(result.status) == len(result.final.names)
    assert "determined" in result.status[:6]
    assert set(result.answer_source) <= {"balance", "prior"}
    determined = np.array([s == "determined" for s in result.status[:6]])
    truth = np.asarray(run.flight.true_theta)
    final = result.final.theta
    assert np.all(np.abs(final.value - truth)[determined] <= Z95 * final.sigma[determined])
    assert result.balance.holdout is not None and result.balance.holdout.force_ratio < 1.0
    doc = result_to_json(result, run.config, simulated_log)
    assert doc["filter"] is None and doc["holdout"]["force_ratio"] < 1.0
    assert [doc["parameters"][n]["status"] for n in PARAMETER_NAMES] == list(result.status[:6])
    assert any("could not follow this flight" in n for n in result.notes)


def test_a_flight_neither_estimate_answers_is_refused_in_one_line(
    simulated_log: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No balance answer and a refusing filter: one refusal naming both reasons."""
    def balance_refuses(flight, config, prior=None, settings=None):
        raise JobFailedError(f"{flight.source}: the force and torque balance determines nothing")

    monkeypatch.setattr(answer, "fit_wrench_balance", balance_refuses)
    with pytest.raises(JobFailedError) as info:
        estimate_job.run_estimate(simulated_log, simulated_log.parent / "prior.toml",
                                    filter_estimate=_filter_refuses)
    message = str(info.value)
    assert "\n" not in message and "determines nothing" in message and "(test)" in message


@pytest.mark.slow
def test_filter_and_balance_agree_on_a_clean_flight(simulated_log: Path) -> None:
    """Clean simulated flight: the filter answers, the balance checks it without a mismatch,
    and every determined parameter covers the truth."""
    run = estimate_job.run_estimate(simulated_log, simulated_log.parent / "prior.toml")
    result = run.result
    assert result.filter_refusal is None and result.mismatch == ()
    assert "filter" in result.answer_source
    determined = np.array([s == "determined" for s in result.status[:6]])
    truth = np.asarray(run.flight.true_theta)
    final = result.final.theta
    assert determined[0]
    assert np.all(np.abs(final.value - truth)[determined] <= Z95 * final.sigma[determined])


def test_a_refused_filters_measurement_sigma_is_the_one_reported(simulated_log: Path) -> None:
    """Where the filter ran and was refused (a negative c_T here), the answer names the
    pose σ that filter used, not the vehicle file's."""
    def refused_filter(flight, config, settings=None, reference=None):
        result = estimate_parameters(flight, config, settings, reference)
        final = result.final
        value = final.value.copy()
        value[0] = -value[0]
        return replace(result, refined=None, measurement_sigma=(0.05, 0.02),
                       filtered=ParameterEstimate(value, final.covariance, final.names))

    run = estimate_job.run_estimate(simulated_log, simulated_log.parent / "prior.toml",
                                    filter_estimate=refused_filter)
    assert run.result.filter_refusal is not None
    assert run.result.measurement_sigma == (0.05, 0.02)
