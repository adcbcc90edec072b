"""Tests of the offline simulator, its controller and its flight logs."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.controller import GeometricController, reference_samples
from mavsysid.flight.offline.effects import ConstantWrench, TruthEffect
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.dynamics import ATT, POS
from mavsysid.vehicle.rotation import quat_conjugate, quat_log, quat_multiply
from mavsysid.vehicle.trajectory import PiecewisePolynomial

from mavsysid.errors import InputError


def _hover(duration: float, position=(0.0, 0.0, 1.0), yaw: float = 0.0) -> PiecewisePolynomial:
    knot = np.zeros((2, 5, 3))
    knot[:, 0] = position
    return PiecewisePolynomial.from_waypoints(
        np.array([0.0, duration]), knot, np.array([[yaw, 0, 0], [yaw, 0, 0]]))


@pytest.fixture(scope="module")
def excitation_flight(tmp_path_factory):
    """The reference vehicle flying the built-in 30 s excitation, logged to disk."""
    from mavsysid.vehicle.config import load_vehicle

    cfg = load_vehicle("firefly")
    directory = tmp_path_factory.mktemp("flight") / "excitation"
    result = Simulator(cfg).run(excitation_trajectory(), directory)
    return cfg, result, directory


def test_closed_loop_tracks_excitation(excitation_flight):
    """Firefly tracks the 30 s excitation with position RMS < 5 cm and no saturation."""
    _, result, _ = excitation_flight
    assert result.times[-1] == pytest.approx(30.0)
    assert result.position_rms < 0.05
    assert result.saturated_fraction == 0.0


@pytest.mark.parametrize("name", ["quad_x", "micro_quad"])
def test_closed_loop_tracks_on_other_scales(name):
    """The same controller gains track on a 1 kg quad and a 30 g quad (scale invariance)."""
    from mavsysid.vehicle.config import load_vehicle

    result = Simulator(load_vehicle(name)).run(excitation_trajectory())
    assert result.position_rms < 0.05
    assert result.saturated_fraction == 0.0


def test_pose_log_holds_noisy_truth(excitation_flight):
    """pose.csv is the truth plus motion-capture noise of the configured σ."""
    cfg, result, directory = excitation_flight
    log = read_pose_log(directory / "pose.csv", cfg.rotor_count)
    assert len(log) == result.times.size == 3001
    np.testing.assert_allclose(log.t, result.times, atol=1e-9)
    pos_err = log.position - result.states[:, POS]
    att_err = quat_log(quat_multiply(quat_conjugate(result.states[:, ATT]), log.quaternion))
    sigma_p, sigma_a = cfg.noise.position_sigma, cfg.noise.attitude_sigma
    # 9003 samples per block: the sample σ is within 3 % of the configured one.
    assert np.std(pos_err) == pytest.approx(sigma_p, rel=0.03)
    assert np.std(att_err) == pytest.approx(sigma_a, rel=0.03)
    assert abs(np.mean(pos_err)) < 4 * sigma_p / np.sqrt(pos_err.size)


def test_logged_rotor_speeds_are_the_lagged_actual_ones(excitation_flight):
    """The log carries actual (lagged) speeds, which trail the commands by the motor lag."""
    cfg, result, directory = excitation_flight
    log = read_pose_log(directory / "pose.csv", cfg.rotor_count)
    np.testing.assert_allclose(log.rotor_speeds, result.rotor_speeds, atol=1e-3)
    assert np.abs(result.rotor_speeds - result.commands).max() > 1.0
    # First-order lag: ṅ = (n_cmd - n)/τ; check the sign agreement of ṅ and n_cmd - n.
    dn = np.gradient(result.rotor_speeds, result.times, axis=0)
    gap = result.commands - result.rotor_speeds
    big = np.abs(gap) > 2.0
    assert np.mean(np.sign(dn[big]) == np.sign(gap[big])) > 0.95


def test_meta_and_truth_are_recorded(excitation_flight):
    """meta.json says complete with the true parameters; truth.csv holds the true state."""
    cfg, result, directory = excitation_flight
    meta = read_meta(directory / "meta.json")
    assert meta["status"] == "complete"
    assert meta["samples"] == 3001
    assert meta["truth"]["parameters"]["c_T"] == cfg.parameters.c_T
    assert meta["truth"]["motor_time_constant_s"] == cfg.motor.time_constant
    assert meta["vehicle"]["name"] == "firefly"
    assert meta["seed"] == 0
    truth = read_pose_log(directory / "truth.csv", cfg.rotor_count)
    np.testing.assert_allclose(truth.position, result.states[:, POS], atol=1e-6)


def test_same_seed_gives_identical_logs(firefly, tmp_path):
    """A seeded flight is reproducible to the byte; another seed changes the noise."""
    traj = excitation_trajectory(ExcitationSpec(duration=10.0))
    texts = []
    for seed, name in ((3, "a"), (3, "b"), (4, "c")):
        settings = SimulationSettings(seed=seed)
        Simulator(firefly, settings=settings).run(traj, tmp_path / name)
        texts.append((tmp_path / name / "pose.csv").read_text())
    assert texts[0] == texts[1]
    assert texts[0] != texts[2]


def test_noise_free_log_equals_truth(firefly, tmp_path):
    """With sensor noise off, the pose log is the true pose."""
    settings = SimulationSettings(sensor_noise=False)
    result = Simulator(firefly, settings=settings).run(_hover(2.0), tmp_path / "f")
    log = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    np.testing.assert_allclose(log.position, result.states[:, POS], atol=1e-6)


def test_motor_lag_can_be_switched_off(firefly):
    """Without motor lag the actual rotor speeds equal the commands held over each tick."""
    settings = SimulationSettings(motor_lag=False)
    result = Simulator(firefly, settings=settings).run(
        excitation_trajectory(ExcitationSpec(duration=10.0)))
    np.testing.assert_allclose(result.rotor_speeds, result.commands, atol=1e-9)


def test_constant_wrench_effect_shifts_hover_by_force_over_stiffness(firefly):
    """A body force F on the truth side offsets hover by F / (m k_p) (PD position loop)."""
    force = np.array([0.3, -0.2, 0.0])
    gains = GeometricController(firefly).gains
    effect = ConstantWrench(force=force)
    result = Simulator(firefly, effects=[effect]).run(_hover(8.0))
    offset = result.states[-1, POS] - result.reference_position[-1]
    expected = force / (firefly.mass * gains.position_frequency**2)
    np.testing.assert_allclose(offset[:2], expected[:2], rtol=0.05)


def test_sensor_effect_changes_only_the_log(firefly, tmp_path):
    """A measure_pose effect shifts what is logged but not what is flown."""

    class Offset(TruthEffect):
        name = "marker_offset"

        def measure_pose(self, t, position, quaternion):
            return position + np.array([0.0, 0.0, 0.1]), quaternion

    settings = SimulationSettings(sensor_noise=False)
    result = Simulator(firefly, settings=settings, effects=[Offset()]).run(
        _hover(1.0), tmp_path / "f")
    log = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    shift = log.position - result.states[:, POS]
    np.testing.assert_allclose(shift, np.tile([0.0, 0.0, 0.1], (len(log), 1)), atol=1e-6)
    np.testing.assert_allclose(result.states[:, 2], 1.0, atol=1e-6)
    assert read_meta(tmp_path / "f" / "meta.json")["truth"]["effects"][0]["name"] == "marker_offset"


def test_interrupted_flight_keeps_what_was_recorded(firefly, tmp_path):
    """An abort mid-flight leaves a readable log up to the abort and meta status 'aborted'."""

    def stop(t, duration):
        if t >= 3.0:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        Simulator(firefly).run(_hover(10.0), tmp_path / "f", progress=stop)
    log = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    assert log.t[-1] == pytest.approx(3.0)
    assert read_meta(tmp_path / "f" / "meta.json")["status"] == "aborted"


@pytest.mark.parametrize(("physics", "control", "log"), [(400, 400, 100), (1000, 300, 100),
                                                          (1000, 500, 300)])
def test_inconsistent_rates_are_rejected(firefly, physics, control, log):
    """Physics below 500 Hz or rates that do not divide evenly are an InputError."""
    settings = SimulationSettings(physics_rate=physics, control_rate=control, log_rate=log)
    with pytest.raises(InputError):
        Simulator(firefly, settings=settings).run(_hover(1.0))


def test_controller_reference_matches_flatness_at_hover(firefly):
    """At hover the reference rows hold the hover point, yaw and zero rates."""
    ref = reference_samples(_hover(1.0, (1, 2, 3), 0.4), np.array([0.0, 0.5]), firefly)
    np.testing.assert_allclose(ref[:, 0:3], [[1, 2, 3]] * 2)
    np.testing.assert_allclose(ref[:, 9], 0.4)
    np.testing.assert_allclose(ref[:, 10:], 0.0, atol=1e-12)
