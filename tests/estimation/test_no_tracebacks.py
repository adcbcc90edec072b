"""0 tracebacks: ``estimate`` and ``diagnose`` on every log the simulator makes.

For each catalogue effect hidden on the truth side (wind included), and for the realistic
sensor path (on-board estimator pose, 500 Hz with jitter and dropped samples, coarse
stamps), a short flight is simulated and both commands run through the console script's
entry point. Each must exit 0, or refuse with a documented code (2: bad input, 3: the job
could not be done) and its reason in one line, never an internal error (exit 1) or a
traceback.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mavsysid.estimation.filter.ekf import ParameterEKF
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.results import ParameterEstimate
from mavsysid.flight.offline.log_timing import LogTiming
from mavsysid.vehicle.config import load_vehicle
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.model_effects import EFFECTS, effect_from_values

from mavsysid.cli.main import main
from mavsysid.errors import LogFormatError
from tests.support.hidden import HIDDEN_MAGNITUDES, ground_trajectory, hidden_flight
from tests.support.realistic import realistic_micro_quad_flight

#: s: the shortest flight `diagnose` accepts (10 s) with a margin for dropped samples.
_DURATION = 12.0


def _run_clean(capsys: pytest.CaptureFixture[str], command: str, argv: list[str]) -> None:
    """Run one command; assert a documented exit and, on refusal, one line saying why."""
    capsys.readouterr()
    code = main([command, *argv, "-q"])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert "internal error" not in err, err
    assert code in (0, 2, 3), (code, err)
    if code:
        lines = [line for line in err.splitlines() if line.startswith(f"mavsysid {command}:")]
        assert len(lines) == 1 and ": error: " in lines[0], err
        assert err.rstrip().endswith(lines[0]), err


def _estimate_and_diagnose(capsys: pytest.CaptureFixture[str], pose: Path,
                           vehicle: str) -> None:
    _run_clean(capsys, "estimate", [str(pose), "--vehicle", vehicle])
    _run_clean(capsys, "diagnose", [str(pose), "--vehicle", vehicle])


def test_every_catalogue_effect_is_covered() -> None:
    assert set(HIDDEN_MAGNITUDES) == set(EFFECTS)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(HIDDEN_MAGNITUDES))
def test_hidden_effect_flight(name: str, tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    config = load_vehicle("firefly")
    ground = name == "ground_effect"  # its trajectory has fixed descents over 30 s
    hidden_flight(config, tmp_path / "f", [effect_from_values(name, HIDDEN_MAGNITUDES[name])],
                  seed=3, duration=_DURATION,
                  trajectory=ground_trajectory() if ground else None)
    _estimate_and_diagnose(capsys, tmp_path / "f" / "pose.csv", "firefly")


@pytest.mark.slow
@pytest.mark.parametrize("timing", [
    LogTiming(),
    # A 1 ms logger clock at 500 Hz with jitter: some stamps coincide.
    LogTiming(jitter=5e-4, resolution=1e-3),
], ids=["jitter-gaps", "coarse-stamps"])
def test_realistic_sensor_path(timing: LogTiming, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    flight = realistic_micro_quad_flight(tmp_path / "f", seed=4, duration=_DURATION,
                                         timing=timing)
    _estimate_and_diagnose(capsys, flight.pose, "micro_quad")


@pytest.mark.slow
def test_stamps_a_microsecond_apart(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A µs logger clock with jitter writes samples 1 µs apart: no zero or tiny step crash."""
    flight = realistic_micro_quad_flight(tmp_path / "f", seed=5, duration=_DURATION,
                                         effects=("wind",), sensor_path=False)
    frame = pd.read_csv(flight.pose)
    t = frame["t"].to_numpy(copy=True)
    rows = np.random.default_rng(5).choice(np.arange(1, t.size - 1, 2), 50, replace=False)
    t[rows] = t[rows - 1] + 1e-6
    t[0 + 1] = t[0] + 1e-6  # the very first step too: the filter starts from it
    frame["t"] = t
    frame.to_csv(flight.pose, index=False, float_format="%.10g", lineterminator="\n")
    _estimate_and_diagnose(capsys, flight.pose, "micro_quad")


def _hover_filter(t: np.ndarray) -> tuple[ParameterEKF, FlightData]:
    """A quad_x logged hovering at 1 m (0.5 mm position noise) at times ``t``, and its filter."""
    config = load_vehicle("quad_x")
    hover = float(np.sqrt(config.mass * GRAVITY / (4 * config.parameters.c_T)))
    position = np.random.default_rng(1).normal([0.0, 0.0, 1.0], 5e-4, (t.size, 3))
    flight = FlightData(t, position, np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1)),
                        np.full((t.size, 4), hover), "hover.csv")
    prior = ParameterEstimate(config.theta, np.diag((0.5 * config.theta) ** 2))
    return ParameterEKF(config, prior, (5e-4, 1e-3)), flight


def test_filter_refuses_a_repeated_stamp_in_one_line() -> None:
    t = np.arange(400) * 0.01
    t[200] = t[199]
    ekf, flight = _hover_filter(t)
    with pytest.raises(LogFormatError, match=r"^hover.csv: the sample times must increase"):
        ekf.run(flight, (0.003, 0.5, 0.03, 0.5))


def test_filter_start_spans_a_sample_period_after_a_microsecond_step() -> None:
    """The finite-difference start is not 0.5 mm of noise over 1 µs (500 m/s)."""
    t = np.arange(400) * 0.01
    t[1] = t[0] + 1e-6
    ekf, flight = _hover_filter(t)
    run = ekf.run(flight, (0.003, 0.5, 0.03, 0.5))
    assert np.all(np.abs(run.states[0, 3:6]) < 0.5)
    assert np.all(np.isfinite(run.estimate.value))
