"""Accuracy of the estimation pipeline on simulated flights (a few seeds; bench/ has more)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation.filter.estimator import EstimatorSettings, estimate_parameters
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError

CORE = [0, 2, 3, 4, 5]  # c_T, c_M, j_x, j_y, j_z


@pytest.mark.parametrize(("name", "seeds"), [("firefly", (0, 1, 2)), ("quad_x", (0,)),
                                             ("micro_quad", (0,))])
@pytest.mark.slow
def test_excitation_flight_is_identified_accurately(simulate_flight, prior_config, name, seeds):
    """Priors ±50 % off: final error < 5 % (median), < 10 % worst on the core, within 3σ."""
    truth_cfg = load_vehicle(name)
    errors, z = [], []
    for seed in seeds:
        flight = simulate_flight(truth_cfg, seed)
        result = estimate_parameters(flight, prior_config(truth_cfg, seed))
        err = (result.final.value - truth_cfg.theta) / truth_cfg.theta
        errors.append(np.abs(err))
        z.append(np.abs(result.final.value - truth_cfg.theta) / result.final.sigma)
    errors, z = np.array(errors), np.array(z)
    assert np.all(np.median(errors, axis=0) < 0.05), np.median(errors, axis=0)
    assert np.all(errors[:, CORE] < 0.10), errors
    assert np.mean(z < 3.0) >= 0.95, z


@pytest.mark.slow
def test_refinement_beats_the_filter_on_short_flights(simulate_flight, prior_config):
    """On 10 s flights the refined median error is ≤ 0.7× the filter's for every parameter."""
    truth_cfg = load_vehicle("firefly")
    filt, ref = [], []
    for seed in range(6):
        flight = simulate_flight(truth_cfg, seed, duration=10.0)
        result = estimate_parameters(flight, prior_config(truth_cfg, seed))
        filt.append(np.abs(result.filtered.value / truth_cfg.theta - 1.0))
        ref.append(np.abs(result.refined.value / truth_cfg.theta - 1.0))
    ratio = np.median(ref, axis=0) / np.median(filt, axis=0)
    assert np.all(ratio <= 0.7), ratio


def test_filter_only_settings_skip_refinement(simulate_flight):
    """With refine off, the result carries only the filter's estimate."""
    cfg = load_vehicle("firefly")
    result = estimate_parameters(simulate_flight(cfg, 0, duration=10.0), cfg,
                                 EstimatorSettings(refine=False))
    assert result.refined is None
    assert result.final is result.filtered


def test_convergence_times_are_reported_against_the_truth(simulate_flight, prior_config):
    """Convergence time is within the flight for well-excited parameters, from the truth."""
    cfg = load_vehicle("firefly")
    flight = simulate_flight(cfg, 1)
    result = estimate_parameters(flight, prior_config(cfg, 1), EstimatorSettings(refine=False))
    np.testing.assert_array_equal(result.true_theta, cfg.theta)
    ct = result.convergence_time
    assert np.all(np.isfinite(ct[[0, 3, 4]]))
    assert np.all((ct[np.isfinite(ct)] >= 0.0) & (ct[np.isfinite(ct)] <= flight.duration))


def test_too_short_and_mismatched_flights_are_refused(simulate_flight):
    """Less than 2 s of data, or a rotor count unlike the vehicle's, is an InputError."""
    cfg = load_vehicle("firefly")
    flight = simulate_flight(cfg, 0, duration=10.0)
    with pytest.raises(InputError, match="at least 2 s"):
        estimate_parameters(flight.time_slice(0.0, 1.5), cfg)
    with pytest.raises(InputError, match="rotor"):
        estimate_parameters(flight, load_vehicle("quad_x"))


def test_segmented_flight_refines_on_its_longest_segment(simulate_flight):
    """A flight split by a gap is filtered whole and refined on its longest segment only,
    with a note; both estimates are finite and near the truth."""
    cfg = load_vehicle("firefly")
    flight = simulate_flight(cfg, 4, duration=14.0)
    keep = ~((flight.t > 4.0) & (flight.t < 4.5))
    second = int(np.searchsorted(flight.t[keep], 4.5))
    flight = replace(flight, t=flight.t[keep], position=flight.position[keep],
                     quaternion=flight.quaternion[keep],
                     rotor_speeds=flight.rotor_speeds[keep], segment_starts=(0, second))
    result = estimate_parameters(flight, cfg)
    note = [n for n in result.notes if n.startswith("batch refinement on the longest segment")]
    assert note and "t = 4.500 to" in note[0] and "2 of 2" in note[0], result.notes
    assert result.history.t.shape == flight.t.shape
    for estimate in (result.filtered, result.refined):
        error = np.abs(estimate.value[CORE] / flight.true_theta[CORE] - 1.0)
        assert (error < 0.1).all(), error
