"""The diagnosis answers where the model does not fit: what it needs, not a reason to stop.

The truth flies rotor drag linear in rotor speed *instead of* the paper's quadratic law
(RotorPy's form, with the axial inflow term k_z), at the Firefly's hover-equivalent drag;
the vehicle file holds the paper's model. The diagnosis must name the linear drag and
report c_D ≈ 0 beside it (at the bound), not refuse it as "physically impossible".
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mavsysid.discrepancy.diagnosis import diagnose_flight
from mavsysid.estimation.flight import FlightData
from mavsysid.pipeline.diagnose import run_diagnose
from mavsysid.vehicle.config import GRAVITY, load_vehicle
from mavsysid.vehicle.model_effects import RotorDragLinear, effect_from_values

from mavsysid.errors import JobFailedError
from tests.support.hidden import HIDDEN_MAGNITUDES, hidden_flight


def _linear_drag_flight(directory: Path) -> tuple[FlightData, float]:
    """Firefly with c_D = 0 and a hidden linear rotor drag of the same hover drag."""
    config = load_vehicle("firefly")
    c_t, c_d = config.theta[0], config.theta[1]
    n_h = np.sqrt(config.mass * GRAVITY / (config.rotor_count * c_t))
    k = c_t * c_d * n_h
    truth = config.theta.copy()
    truth[1] = 0.0
    flight = hidden_flight(config, directory, [RotorDragLinear(k=k, k_z=0.8 * k)], seed=4,
                           true_theta=truth)
    return flight, k


@pytest.mark.slow
def test_vanishing_c_d_beside_linear_rotor_drag_is_an_answer(tmp_path):
    """Named rotor_drag_linear (k and k_z in their CIs), c_D ≈ 0 accepted, exit 0."""
    flight, k = _linear_drag_flight(tmp_path / "f")
    run = run_diagnose(flight.source, "firefly", with_nis=False)
    d = run.diagnosis
    assert [f.effect.name for f in d.effects] == ["rotor_drag_linear"]
    (lo_k, hi_k), (lo_z, hi_z) = d.effects[0].ci95
    assert lo_k <= k <= hi_k and lo_z <= 0.8 * k <= hi_z
    c_d, sigma = d.theta_after[1], d.theta_after_sigma[1]
    prior = run.config.theta[1]
    assert abs(c_d) < 0.05 * prior and abs(c_d) < 3.0 * sigma  # at the bound, not a drag


def test_a_filter_that_cannot_follow_either_model_costs_only_the_nis(monkeypatch, tmp_path):
    """With an effect named, a diverged EKF is a note (NIS missing), not a refusal."""
    import mavsysid.estimation as estimation

    config = load_vehicle("firefly")
    flight = hidden_flight(config, tmp_path / "f",
                           [effect_from_values("body_drag", HIDDEN_MAGNITUDES["body_drag"])],
                           seed=1)

    def diverges(*args, **kwargs):
        raise JobFailedError("x.csv: the parameter filter diverged")

    monkeypatch.setattr(estimation, "estimate_with_effects", diverges)
    d = diagnose_flight(flight, config, config.theta * 1.05, with_nis=True)
    assert [f.effect.name for f in d.effects][:1] == ["body_drag"]
    assert d.gap.before.nis_mean is None and d.gap.after.nis_mean is None
    assert any(n.startswith("no NIS without the named effects: x.csv") for n in d.notes)
    assert any(n.startswith("no NIS with the named effects: x.csv") for n in d.notes)
