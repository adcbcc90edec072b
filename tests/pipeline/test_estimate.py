"""Tests of the estimate job (`mavsysid.pipeline.estimate`): it refuses an impossible θ
before anything is written."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from mavsysid.pipeline import estimate as estimate_job
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

from mavsysid.cli.main import main

PRIOR = load_vehicle("quad_x").theta
PRIOR_SIGMA = 0.5 * PRIOR


def _stub_result(theta: np.ndarray) -> SimpleNamespace:
    final = SimpleNamespace(value=theta, sigma=0.05 * np.abs(theta))
    prior = SimpleNamespace(value=PRIOR, sigma=PRIOR_SIGMA)
    return SimpleNamespace(final=final, prior=prior, equation_error=None, effects=())


@pytest.fixture
def stub_estimation(monkeypatch: pytest.MonkeyPatch) -> Callable[[np.ndarray], None]:
    """Replace reading and estimating in `estimate_job` by stubs returning a given θ."""

    def use(theta: np.ndarray) -> None:
        monkeypatch.setattr(estimate_job, "load_flight",
                            lambda log, config, **kw: SimpleNamespace(source=str(log)))
        monkeypatch.setattr(estimate_job, "check_kinematics", lambda flight: None)
        monkeypatch.setattr(estimate_job, "estimate_parameters",
                            lambda flight, config, settings=None: _stub_result(theta))

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
