"""Real autopilot logs: an honest answer or one clear line.

Every log in ``../shared/real-logs/`` (public PX4 and ArduPilot logs, PROVENANCE.md) with
every shipped vehicle, through the console script in-process: ``estimate`` and
``diagnose`` exit with 0, 2 or 3, never show a traceback, refuse in exactly one line that
names the file, and exit 0 only with a physically possible θ. The physical rules are
written here independently of `mavsysid.estimation.checks`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from mavsysid.vehicle.config import PARAMETER_NAMES, SHIPPED_VEHICLES, load_vehicle

from mavsysid.cli.main import main

REAL_LOGS = Path(__file__).resolve().parents[2] / ".." / "shared" / "real-logs"
LOGS = sorted(p.name for p in REAL_LOGS.glob("*")
              if p.suffix.lower() in (".ulg", ".bin", ".tlog")) if REAL_LOGS.is_dir() else []

# Independent statement of "physically possible": positive, J a rigid body within a 25 %
# slack (the configs' tolerance), and within a factor 10 of the vehicle's prior.
SLACK = 0.25
FACTOR = 10.0

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not LOGS, reason=f"no real logs in {REAL_LOGS}"),
    # As the console script runs: a numerical RuntimeWarning is not an error there.
    pytest.mark.filterwarnings("default::RuntimeWarning"),
]


def _check_possible(theta: dict[str, float], prior: dict[str, float]) -> None:
    for name in PARAMETER_NAMES:
        value = theta[name]
        assert math.isfinite(value) and value > 0.0, f"{name} = {value}"
        assert 1.0 / FACTOR <= value / prior[name] <= FACTOR, f"{name} = {value} vs {prior[name]}"
    j = [theta["j_x"], theta["j_y"], theta["j_z"]]
    for c in range(3):
        assert j[c] <= (1.0 + SLACK) * (j[(c + 1) % 3] + j[(c + 2) % 3]), f"J = {j}"


def _run(command: str, log: str, vehicle: str, out: Path,
         capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main([command, str(REAL_LOGS / log), "--vehicle", vehicle, "-o", str(out)])
    err = capsys.readouterr().err
    assert code in (0, 2, 3), f"exit {code}: {err}"
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if ": error: " in line]
    if code != 0:
        assert len(errors) == 1, err
        assert log in errors[0], f"the refusal does not name the file: {errors[0]}"
        assert not out.exists(), "a refused job wrote its output"
    else:
        assert not errors, err
    return code, err


@pytest.mark.parametrize("vehicle", SHIPPED_VEHICLES)
@pytest.mark.parametrize("log", LOGS)
def test_estimate_real_log(log: str, vehicle: str, tmp_path: Path,
                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "estimate.json"
    code, _ = _run("estimate", log, vehicle, out, capsys)
    if code == 0:
        data = json.loads(out.read_text())
        params = data["parameters"]
        prior = dict(zip(PARAMETER_NAMES, load_vehicle(vehicle).theta, strict=True))
        _check_possible({n: params[n]["value"] for n in PARAMETER_NAMES}, prior)
        for name in PARAMETER_NAMES:
            sigma = params[name]["sigma"]
            assert sigma is not None and math.isfinite(sigma) and sigma > 0.0, name


@pytest.mark.parametrize("vehicle", SHIPPED_VEHICLES)
@pytest.mark.parametrize("log", LOGS)
def test_diagnose_real_log(log: str, vehicle: str, tmp_path: Path,
                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "diagnosis.json"
    code, _ = _run("diagnose", log, vehicle, out, capsys)
    if code == 0:
        theta = json.loads(out.read_text())["theta"]
        prior = dict(zip(PARAMETER_NAMES, load_vehicle(vehicle).theta, strict=True))
        for key in ("refit_without_effects", "refit_with_effects"):
            _check_possible(theta[key], prior)
