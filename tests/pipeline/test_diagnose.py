"""Tests of the diagnose job (`mavsysid.pipeline.diagnose`): without a balance answer it
refuses an impossible θ before anything is written; from the balance's θ it answers."""

from __future__ import annotations

import dataclasses
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
    monkeypatch.setattr(diagnose_job, "balance_start", lambda *a, **kw: (None, None))
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
    monkeypatch.setattr(diagnose_job, "balance_start", lambda *a, **kw: (None, None))
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


def test_diagnose_from_the_balance_keeps_its_theta_when_the_refit_is_impossible(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """θ from the balance: an impossible refit with the named effects is a note, not a
    refusal, and the balance's θ stands as the answer."""
    balance = _theta(j_x=PRIOR[3] * 1.1)
    refit = _theta(j_z=3.0 * (PRIOR[3] + PRIOR[4]))
    monkeypatch.setattr(diagnose_job, "load_flight",
                        lambda log, config, **kw: SimpleNamespace(source=str(log)))
    monkeypatch.setattr(diagnose_job, "check_kinematics", lambda flight: None)
    determined = np.array([True, False, False, True, True, True])
    monkeypatch.setattr(diagnose_job, "balance_start", lambda *a, **kw: (
        diagnose_job.BalanceStart(balance, determined, 0.06, "fitted here"), None))
    named = SimpleNamespace(name="body_drag")
    seen = {}

    def diagnosed(flight, config, theta, settings, known, **kw):
        window = None if settings is None else settings.smoother.window
        seen.update(theta=theta, window=window, free=kw.get("free_theta"))
        return SimpleNamespace(theta_before=(PRIOR if theta is None else theta).copy(),
                               theta_after=refit,
                               theta_after_sigma=None, effects=(named,),
                               augmented_effects=(named,), notes=())

    monkeypatch.setattr(diagnose_job, "diagnose_flight", diagnosed)
    monkeypatch.setattr(diagnose_job, "replace",
                        lambda d, **kw: SimpleNamespace(**{**vars(d), **kw})
                        if isinstance(d, SimpleNamespace) else dataclasses.replace(d, **kw))
    d = diagnose_job.run_diagnose("flight.ulg", "quad_x").diagnosis
    assert np.array_equal(seen["theta"], balance) and seen["window"] == 0.06
    assert np.array_equal(seen["free"], determined)
    assert np.array_equal(d.theta_after, balance)
    assert any("triangle inequality" in n and "balance's θ is kept" in n for n in d.notes)
    assert any("c_D, c_M not determined" in n for n in d.notes)


@pytest.mark.slow
def test_diagnose_answers_a_flight_with_on_board_estimator_noise(tmp_path: Path) -> None:
    """A flight logged through an on-board estimator (correlated pose noise, jitter, gaps)
    and a prior 30–50 % off, diagnosed as the workflow does (estimate, then diagnose
    --estimate): no refusal, and the held-out gap before and after; θ from the balance
    holds what it does not determine at the prior."""
    from mavsysid.estimation.report.text import write_estimate_json
    from mavsysid.pipeline.estimate import run_estimate

    from tests.support.realistic import prior_config, realistic_micro_quad_flight

    flight = realistic_micro_quad_flight(tmp_path / "f", seed=2, duration=30.0)
    vehicle, prior = prior_config(flight.config, tmp_path / "prior.toml", seed=2)
    estimated = run_estimate(flight.pose, vehicle)
    estimate = tmp_path / "estimate.json"
    write_estimate_json(estimate, estimated.result, estimated.config, flight.pose)
    run = diagnose_job.run_diagnose(flight.pose, vehicle, estimate, with_nis=False)
    d = run.diagnosis
    start = [n for n in d.notes if n.startswith("θ from the force and torque balance")]
    if start:
        held = np.array([n in start[0].split(";")[-1] for n in PARAMETER_NAMES])
        assert np.array_equal(d.theta_identified[held], prior[held])
    g = d.gap.held_out
    assert g is not None and g.rows > 100
    for which in ("before", "after"):
        assert all(np.isfinite(r) and r > 0 for r in g.ratios(which))
    # The estimate predicts the held-out forces better than the 30–50 % prior does.
    assert g.ratios("before")[0] < 1.0
    if d.effects:
        assert d.gap.after.rms[list(d.gap.flagged_axes)].sum() \
            < d.gap.before.rms[list(d.gap.flagged_axes)].sum()


def test_an_estimate_answered_by_the_balance_is_diagnosed_despite_a_prior_bound(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """An estimate.json whose balance determines j_x, j_y below the prior j_z (the triangle
    inequality broken by the prior's j_z) is diagnosed from the balance, with a note; the
    same θ without a balance section is refused."""
    theta = _theta(j_x=PRIOR[5] / 4, j_y=PRIOR[5] / 4)
    status = ["determined", "not determined", "not determined", "determined", "determined",
              "not determined"]
    body = {"parameters": {n: {"value": float(v)} for n, v in zip(PARAMETER_NAMES, theta,
                                                                   strict=True)}}
    balance = {"parameters": {n: {"value": float(v), "status": s} for n, v, s in
                              zip(PARAMETER_NAMES, theta, status, strict=True)},
               "choices": {"window_s": 0.08}}
    estimate = tmp_path / "estimate.json"
    estimate.write_text(json.dumps({**body, "balance": balance, "filter_refusal": "diverged"}))
    monkeypatch.setattr(diagnose_job, "load_flight",
                        lambda log, config, **kw: SimpleNamespace(source=str(log)))
    monkeypatch.setattr(diagnose_job, "check_kinematics", lambda flight: None)
    seen = {}

    def diagnosed(flight, config, theta, settings, known, **kw):
        seen.update(theta=theta, window=settings.smoother.window, nis=kw["with_nis"])
        return SimpleNamespace(theta_before=theta.copy(), theta_after=theta.copy(),
                               theta_after_sigma=None, effects=(), augmented_effects=(),
                               notes=())

    monkeypatch.setattr(diagnose_job, "diagnose_flight", diagnosed)
    monkeypatch.setattr(diagnose_job, "check_refits", lambda *a: ())
    monkeypatch.setattr(diagnose_job, "replace",
                        lambda d, **kw: SimpleNamespace(**{**vars(d), **kw})
                        if isinstance(d, SimpleNamespace) else dataclasses.replace(d, **kw))
    notes = diagnose_job.run_diagnose("flight.ulg", "quad_x", estimate).diagnosis.notes
    assert np.array_equal(seen["theta"], theta) and seen["window"] == 0.08
    assert seen["nis"] is False  # the estimate's filter did not follow the flight
    assert any("triangle inequality" in n for n in notes)
    assert any("c_D, c_M, j_z not determined" in n for n in notes)
    estimate.write_text(json.dumps(body))
    with pytest.raises(JobFailedError, match="triangle inequality"):
        diagnose_job.run_diagnose("flight.ulg", "quad_x", estimate)
