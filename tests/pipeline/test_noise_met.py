"""Planning for the noise the estimator met (`mavsysid.pipeline.plan.for_noise_met`, ``plan
--noise-from``): recorded by the estimate, read back, and what it does to the prediction."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from mavsysid.estimation import NoiseMet, read_noise_met, read_set_aside, write_estimate_json
from mavsysid.estimation.filter.estimator import estimate_parameters
from mavsysid.estimation.readers import load_flight
from mavsysid.experiments.data_efficiency import belief_history
from mavsysid.flight.offline.effects import ProcessNoise
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.pipeline.plan import for_noise_met
from mavsysid.planner.rrbt import plan
from mavsysid.planner.settings import PlannerSettings
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError

#: The unmodelled force and moment of the simulated world, × the vehicle file's densities.
WORLD_NOISE = 4.0
#: The pose log's rate, Hz (the planner's default is 100).
POSE_RATE = 50.0


@pytest.fixture(scope="module")
def noisy_flight(tmp_path_factory):
    """A planned 15 s flight flown in a world with 4× the configured process noise and
    logged at 50 Hz, and its estimate."""
    cfg = load_vehicle("firefly")
    planned = plan(cfg, PlannerSettings(budget=15.0, planning_time=np.inf, max_samples=200,
                                        seed=1, refine_steps=300))
    directory = tmp_path_factory.mktemp("noisy") / "flight"
    noise = ProcessNoise(WORLD_NOISE * cfg.noise.force_density,
                         WORLD_NOISE * cfg.noise.moment_density, seed=1)
    Simulator(cfg, settings=SimulationSettings(seed=1, log_rate=POSE_RATE),
              effects=[noise]).run(planned.trajectory, directory)
    result = estimate_parameters(load_flight(directory / "pose.csv", cfg), cfg)
    return cfg, planned.trajectory, directory, result


def test_the_estimate_records_the_noise_its_filter_met(noisy_flight):
    """The log's rate and the fitted densities (one scale, near the world's); nothing from
    a refused filter."""
    cfg, _, _, result = noisy_flight
    met = result.noise_met
    assert met is not None
    assert met.pose_rate == pytest.approx(POSE_RATE, rel=1e-6)
    assert replace(result, filter_refusal="refused").noise_met is None
    force = met.force_density / cfg.noise.force_density
    assert force == pytest.approx(met.moment_density / cfg.noise.moment_density, rel=1e-9)
    assert WORLD_NOISE / 1.6 < force < WORLD_NOISE * 1.6


def test_planned_at_the_noise_met_the_predicted_sigma_is_the_reported_one(noisy_flight):
    """The flight's σ predicted at the noise met is what the estimate reports (each within
    0.6–1.6×, their geometric mean within 0.8–1.25×); at the vehicle file's noise and a
    100 Hz pose the prediction is over twice too confident for every parameter."""
    cfg, trajectory, _, result = noisy_flight
    reported = result.final.sigma[:6]
    ratios = {}
    for label, met in (("file", None), ("met", result.noise_met)):
        model, settings = for_noise_met(cfg, PlannerSettings(), met)
        ratios[label] = reported / belief_history(model, trajectory, settings).sigma[-1]
    assert np.all((ratios["met"] > 0.6) & (ratios["met"] < 1.6)), ratios
    assert 0.8 < np.exp(np.mean(np.log(ratios["met"]))) < 1.25, ratios
    assert np.all(ratios["file"] > 2.0), ratios


def test_the_noise_met_goes_through_estimate_json(noisy_flight):
    """Written with the estimate, read back from the file or its flight directory."""
    cfg, _, directory, result = noisy_flight
    write_estimate_json(directory / "estimate.json", result, cfg, directory / "pose.csv")
    assert read_noise_met(directory) == result.noise_met
    assert read_noise_met(directory / "estimate.json") == result.noise_met


def test_for_noise_met_sets_the_models_noise_and_the_pose_rate():
    """Only the noise and the measurement rate change; nothing without a noise."""
    cfg, settings = load_vehicle("firefly"), PlannerSettings(budget=12.0)
    met = NoiseMet(0.05, 0.02, 30.0, 0.3, 0.004)
    model, planned = for_noise_met(cfg, settings, met)
    assert (model.noise.position_sigma, model.noise.attitude_sigma) == (0.05, 0.02)
    assert (model.noise.force_density, model.noise.moment_density) == (0.3, 0.004)
    assert planned == replace(settings, measurement_rate=30.0)
    assert model.theta.tolist() == cfg.theta.tolist() and model.limits == cfg.limits
    assert for_noise_met(cfg, settings, None) == (cfg, settings)


BAD_ESTIMATES = {
    "missing": (None, "no such estimate"),
    "not JSON": ("{", "not a readable estimate.json"),
    "no noise_met": ({"parameters": {}}, "holds no noise_met"),
    "filter refused": ({"noise_met": None}, "holds no noise_met"),
    "negative density": ({"noise_met": {"position_m": 0.05, "attitude_rad": 0.02,
                                        "pose_rate_hz": 50, "force_density": -1,
                                        "moment_density": 0.01}}, "noise_met.force_density"),
    "zero rate": ({"noise_met": {"position_m": 0.05, "attitude_rad": 0.02, "pose_rate_hz": 0,
                                 "force_density": 1, "moment_density": 0.01}},
                  "noise_met.pose_rate_hz"),
}


@pytest.mark.parametrize("content, fragment", BAD_ESTIMATES.values(), ids=BAD_ESTIMATES.keys())
def test_an_unusable_estimate_is_refused_in_one_line(tmp_path, content, fragment):
    path = tmp_path / "estimate.json"
    if content is not None:
        path.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(InputError) as refused:
        read_noise_met(tmp_path)
    message = str(refused.value)
    assert fragment in message and str(path) in message and "\n" not in message


def test_the_median_noise_of_several_flights_is_each_quantitys_median():
    mets = [NoiseMet(0.05, 0.02, 50.0, 0.3, 0.003), NoiseMet(0.04, 0.03, 30.0, 0.5, 0.002),
            NoiseMet(0.06, 0.01, 40.0, 0.2, 0.004)]
    assert NoiseMet.median(mets) == NoiseMet(0.05, 0.02, 40.0, 0.3, 0.003)
    assert NoiseMet.median(mets[:1]) == mets[0]
    with pytest.raises(ValueError):
        NoiseMet.median([])


def test_set_aside_are_the_parameters_the_filter_resolved_and_the_answer_did_not(tmp_path):
    """Filter σ within 12.5 % and the answer not determined: set aside; a parameter the
    filter did not resolve, or one the answer determined, is not."""
    def entry(rel, status=None):
        return {"relative_sigma": rel, **({"status": status} if status else {})}

    statuses = ["determined", "not determined by this flight", "not determined by this flight",
                "determined", "not determined by this flight", "at the bound"]
    filter_rel = [0.001, 0.05, 0.40, 0.02, 0.125, 0.03]
    names = ("c_T", "c_D", "c_M", "j_x", "j_y", "j_z")
    document = {"parameters": {n: entry(0.1, s) for n, s in zip(names, statuses, strict=True)},
                "filter": {n: entry(r) for n, r in zip(names, filter_rel, strict=True)}}
    (tmp_path / "estimate.json").write_text(json.dumps(document))
    assert read_set_aside(tmp_path) == ("c_D", "j_y", "j_z")
    (tmp_path / "estimate.json").write_text(json.dumps({**document, "filter": None}))
    assert read_set_aside(tmp_path) == ()
