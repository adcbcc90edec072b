"""Tests of the diagnose job (`mavsysid.pipeline.diagnose`): it refuses an impossible θ
before anything is written."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from mavsysid.pipeline import diagnose as diagnose_job
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

from mavsysid.errors import JobFailedError

PRIOR = load_vehicle("quad_x").theta


def _theta(**changes: float) -> np.ndarray:
    theta = PRIOR.copy()
    for name, value in changes.items():
        theta[PARAMETER_NAMES.index(name)] = value
    return theta


def test_diagnose_refuses_an_impossible_estimate_file_before_reading_the_log(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
) -> None:
    estimate = tmp_path / "estimate.json"
    theta = _theta(j_x=-0.01)
    estimate.write_text(json.dumps({"parameters": {
        n: {"value": float(v)} for n, v in zip(PARAMETER_NAMES, theta, strict=True)}}))

    def no_read(*args: object, **kwargs: object) -> None:
        raise AssertionError("the log was read after an impossible θ")

    monkeypatch.setattr(diagnose_job, "load_flight", no_read)
    with pytest.raises(JobFailedError, match=r"estimate\.json: identified θ: j_x = -0\.01 "):
        diagnose_job.run_diagnose("flight.ulg", "quad_x", estimate)


def test_diagnose_refuses_an_impossible_refit(monkeypatch: pytest.MonkeyPatch) -> None:
    refit = _theta(c_T=PRIOR[0] / 500.0)
    monkeypatch.setattr(diagnose_job, "load_flight",
                        lambda log, config, **kw: SimpleNamespace(source=str(log)))
    monkeypatch.setattr(diagnose_job, "check_kinematics", lambda flight: None)
    named = SimpleNamespace(name="body_drag")
    monkeypatch.setattr(diagnose_job, "diagnose_flight", lambda *a, **kw: SimpleNamespace(
        theta_before=PRIOR.copy(), theta_after=refit, theta_after_sigma=None,
        effects=(named,), augmented_effects=(named,)))
    with pytest.raises(JobFailedError, match=r"^flight\.ulg: θ refitted with the named "
                       r"effects: c_T = .* is 500× below the prior"):
        diagnose_job.run_diagnose("flight.ulg", "quad_x")


def test_diagnose_notes_an_impossible_refit_the_named_effects_explain(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """θ refitted *without* the named effects breaking the triangle inequality is the
    mismatch they explain: a note, and the diagnosis stands; with none named, a refusal."""
    before = _theta(j_z=1.5 * (PRIOR[3] + PRIOR[4]))
    monkeypatch.setattr(diagnose_job, "load_flight",
                        lambda log, config, **kw: SimpleNamespace(source=str(log)))
    monkeypatch.setattr(diagnose_job, "check_kinematics", lambda flight: None)
    named = SimpleNamespace(name="body_drag")
    diagnosis = SimpleNamespace(theta_before=before, theta_after=_theta(),
                                theta_after_sigma=None, effects=(named,),
                                augmented_effects=(named,), notes=())
    monkeypatch.setattr(diagnose_job, "replace",
                        lambda d, **kw: SimpleNamespace(**{**vars(d), **kw}))
    monkeypatch.setattr(diagnose_job, "diagnose_flight", lambda *a, **kw: diagnosis)
    notes = diagnose_job.run_diagnose("flight.ulg", "quad_x").diagnosis.notes
    assert len(notes) == 1 and "triangle inequality" in notes[0]
    monkeypatch.setattr(diagnose_job, "diagnose_flight", lambda *a, **kw: SimpleNamespace(
        **{**vars(diagnosis), "theta_after": before, "effects": (), "augmented_effects": ()}))
    with pytest.raises(JobFailedError, match=r"^flight\.ulg: θ refitted without effects: J"):
        diagnose_job.run_diagnose("flight.ulg", "quad_x")
