"""Tests of the truth-side effects: catalogue effects hidden in the offline simulator."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.offline.controller import GeometricController
from mavsysid.flight.offline.effects import CatalogEffect, applies_wrench, hidden_effect
from mavsysid.flight.offline.excitation import excitation_trajectory
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import GRAVITY
from mavsysid.vehicle.dynamics import POS
from mavsysid.vehicle.model_effects import EFFECTS, EffectInputs, parse_effect
from mavsysid.vehicle.rotation import quat_normalize, quat_to_matrix
from mavsysid.vehicle.trajectory import PiecewisePolynomial

_QUIET = SimulationSettings(sensor_noise=False)


def _hover(duration: float, position=(0.0, 0.0, 1.0), yaw: float = 0.0) -> PiecewisePolynomial:
    knot = np.zeros((2, 5, 3))
    knot[:, 0] = position
    return PiecewisePolynomial.from_waypoints(
        np.array([0.0, duration]), knot, np.array([[yaw, 0, 0], [yaw, 0, 0]]))


def _effect(spec: str) -> CatalogEffect:
    return hidden_effect(parse_effect(spec))


@pytest.mark.parametrize("spec", [
    "body_drag:k=0.03", "rotor_drag_linear:k=2e-4", "cog_offset:x=0.01,y=-0.02,z=0.005",
    "wind:x=2,y=-1", "thrust_drift:rate=-0.003", "ground_effect:rotor_radius=0.1",
])
def test_adapter_wrench_equals_catalogue_wrench(firefly, spec):
    """The truth adapter's wrench at one state is the catalogue's wrench at that sample."""
    rng = np.random.default_rng(7)
    x = np.concatenate([[0.3, -0.2, 0.25], rng.normal(size=3),
                        quat_normalize(rng.normal(size=4)), rng.normal(size=3)])
    n = rng.uniform(300.0, 700.0, firefly.rotor_count)
    theta = firefly.theta * 1.1
    adapter = _effect(spec)
    adapter.bind(theta, firefly.rotor_positions)
    force, torque = adapter.wrench(12.5, x, n)
    inputs = EffectInputs(np.array([12.5]), x[None, 0:3], x[None, 6:10], x[None, 3:6],
                          x[None, 10:13], n[None], theta, firefly.rotor_positions)
    f_ref, m_ref = parse_effect(spec).wrench(inputs)
    assert np.abs(f_ref).max() + np.abs(m_ref).max() > 0.0
    np.testing.assert_allclose(force, f_ref[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(torque, m_ref[0], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(("name", "wrench"), [
    (name, "wrench" in cls.channels) for name, cls in EFFECTS.items()])
def test_only_wrench_effects_leave_the_fast_path(name, wrench):
    """Only catalogue effects with a wrench channel make the simulator evaluate wrenches."""
    assert applies_wrench(hidden_effect(EFFECTS[name]())) is wrench


def test_hidden_marker_offset_moves_logged_position_by_r_rotated(firefly, tmp_path):
    """pose.csv positions are the true ones plus R r exactly (noise off); attitude unchanged."""
    r = np.array([0.03, -0.01, 0.02])
    effect = _effect(f"marker_offset:x={r[0]},y={r[1]},z={r[2]}")
    traj = excitation_trajectory()
    Simulator(firefly, settings=_QUIET, effects=[effect]).run(traj, tmp_path / "f")
    pose = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    truth = read_pose_log(tmp_path / "f" / "truth.csv", firefly.rotor_count)
    expected = truth.position + quat_to_matrix(truth.quaternion) @ r
    np.testing.assert_allclose(pose.position, expected, atol=2e-6)
    np.testing.assert_allclose(pose.quaternion, truth.quaternion, atol=2e-6)
    assert np.ptp(pose.position - truth.position, axis=0).max() > 0.01  # the vehicle tilts


@pytest.mark.parametrize("delay", [0.02, 0.015])
def test_hidden_pose_delay_shifts_logged_pose_by_delay(firefly, tmp_path, delay):
    """pose.csv at t holds truth.csv's pose at t − d (linear between log samples)."""
    Simulator(firefly, settings=_QUIET, effects=[_effect(f"pose_delay:delay={delay}")]).run(
        excitation_trajectory(), tmp_path / "f")
    pose = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    truth = read_pose_log(tmp_path / "f" / "truth.csv", firefly.rotor_count)
    late = truth.t >= delay
    for axis in range(3):
        shifted = np.interp(truth.t - delay, truth.t, truth.position[:, axis])
        np.testing.assert_allclose(pose.position[late, axis], shifted[late], atol=2e-6)
    # The pose really moved: a delay of d at up to 3 m/s is centimetres.
    assert np.abs(pose.position - truth.position).max() > 0.02


def test_hidden_motor_lag_logs_commands_and_truth_follows_with_tau(firefly, tmp_path):
    """With motor_lag tau: pose.csv holds the commands, and the true speeds lag them by tau."""
    tau = 0.04
    settings = SimulationSettings(sensor_noise=False, log_rate=500.0)
    result = Simulator(firefly, settings=settings, effects=[_effect(f"motor_lag:tau={tau}")]).run(
        excitation_trajectory(), tmp_path / "f")
    pose = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    np.testing.assert_allclose(pose.rotor_speeds, result.commands, atol=1e-3)
    # Row i + 1 logs the command held over [t_i, t_i+1]: n relaxes towards it exactly.
    n, c = result.rotor_speeds, result.commands
    gap0, gap1 = n[:-1] - c[1:], n[1:] - c[1:]
    big = np.abs(gap0) > 5.0
    dt = np.diff(result.times)[:, None] * np.ones_like(gap0)
    fitted = -dt[big] / np.log(gap1[big] / gap0[big])
    assert np.median(fitted) == pytest.approx(tau, rel=1e-3)
    assert read_meta(tmp_path / "f" / "meta.json")["truth"]["motor_time_constant_s"] == tau


def test_hidden_rotor_speed_lag_logs_the_true_speeds_late(firefly, tmp_path):
    """With rotor_speed_lag τ: pose.csv holds a first-order lag of the true speeds."""
    tau = 0.02
    settings = SimulationSettings(sensor_noise=False, log_rate=500.0)
    result = Simulator(firefly, settings=settings,
                       effects=[_effect(f"rotor_speed_lag:tau={tau}")]).run(
        excitation_trajectory(), tmp_path / "f")
    pose = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    lagged = parse_effect("motor_lag:tau=0.02").acting_rotor_speeds(result.times,
                                                                   result.rotor_speeds)
    np.testing.assert_allclose(pose.rotor_speeds, lagged, atol=1e-3)
    assert np.abs(pose.rotor_speeds - result.rotor_speeds).max() > 1.0


def test_hidden_rotor_inertia_yaws_the_body_as_the_rotors_spin_up(firefly):
    """A hidden J_r: the truth's yaw torque is −J_r Σ ε_i ṅ_i over the last tick."""
    adapter = _effect("rotor_inertia:J_r=2e-5")
    adapter.bind(firefly.theta, firefly.rotor_positions, firefly.rotor_directions)
    adapter.reset(0.001)
    x = np.zeros(13)
    x[6] = 1.0
    n0 = np.full(firefly.rotor_count, 500.0)
    n1 = n0 + 0.5 * np.asarray(firefly.rotor_directions)  # a yaw command over 2 ms
    assert np.all(adapter.wrench(0.0, x, n0)[1] == 0.0)  # no history yet
    force, torque = adapter.wrench(0.002, x, n1)
    assert np.all(force == 0.0)
    rate = 0.5 / 0.002
    np.testing.assert_allclose(torque, [0.0, 0.0, -2e-5 * rate * firefly.rotor_count])


def test_thrust_drift_makes_the_controller_spin_up(firefly):
    """c_T falling 8 % over 30 s: hover needs n² higher by 1 / 0.92 at the end."""
    rate = -0.08 / 30.0
    result = Simulator(firefly, settings=_QUIET, effects=[
        _effect(f"thrust_drift:rate={rate}")]).run(_hover(30.0))
    n2 = np.sum(result.rotor_speeds**2, axis=1)
    assert n2[-1] / n2[100] == pytest.approx((1 + rate * 1.0) / (1 + rate * 30.0), rel=0.01)


def test_wind_pushes_a_hovering_vehicle_downwind(firefly):
    """A 2 m/s wind towards +x offsets hover by m g c_D w / (m k_p) along +x."""
    wind = 2.0
    gains = GeometricController(firefly).gains
    result = Simulator(firefly, settings=_QUIET, effects=[_effect(f"wind:x={wind}")]).run(
        _hover(8.0))
    offset = result.states[-1, POS] - result.reference_position[-1]
    expected = GRAVITY * firefly.parameters.c_D * wind / gains.position_frequency**2
    assert offset[0] == pytest.approx(expected, rel=0.05)
    assert abs(offset[1]) < 0.05 * expected


def test_ground_effect_lowers_hover_speeds_near_the_ground(firefly):
    """Hovering with the hubs near one rotor diameter up needs n² lower by the thrust gain."""
    rho = 0.1
    effect = parse_effect(f"ground_effect:rotor_radius={rho}")
    speeds, gains = {}, {}
    for z in (0.1, 3.0):
        result = Simulator(firefly, settings=_QUIET, effects=[hidden_effect(effect)]).run(
            _hover(4.0, (0.0, 0.0, z)))
        speeds[z] = np.sum(result.rotor_speeds[-1] ** 2)
        # The extra lift raises the hover point a little (PD loop): use the final height.
        h = result.states[-1, 2] + firefly.rotor_positions[0, 2]
        gains[z] = 1.0 / (1.0 - (rho / (4.0 * h)) ** 2)
    assert speeds[3.0] / speeds[0.1] == pytest.approx(gains[0.1] / gains[3.0], rel=0.002)
    assert gains[0.1] > 1.02


def test_body_drag_costs_tracking_along_the_velocity(firefly):
    """Body drag 5 % of the weight at 3 m/s makes the vehicle lag its reference (not lead)."""
    k = 0.05 * firefly.mass * GRAVITY / 9.0
    knot = np.zeros((2, 5, 3))
    knot[:, 0] = [(0.0, 0.0, 1.0), (12.0, 0.0, 1.0)]
    knot[:, 1, 0] = 3.0  # constant 3 m/s along x
    traj = PiecewisePolynomial.from_waypoints(np.array([0.0, 4.0]), knot, np.zeros((2, 3)))
    result = Simulator(firefly, settings=_QUIET, effects=[_effect(f"body_drag:k={k}")]).run(
        traj)
    gains = GeometricController(firefly).gains
    error = result.states[-1, POS] - result.reference_position[-1]
    expected = -k * 9.0 / (firefly.mass * gains.position_frequency**2)
    assert error[0] == pytest.approx(expected, rel=0.1)


@pytest.mark.parametrize("spec", ["cog_offset:x=0.01", "cog_offset:y=0.01,z=0.01",
                                  "motor_lag:tau=0.04"])
def test_vehicle_stays_controllable_with_hidden_effect(firefly, spec):
    """The nominal controller still tracks the 30 s excitation within 2 cm RMS."""
    result = Simulator(firefly, settings=_QUIET, effects=[_effect(spec)]).run(
        excitation_trajectory())
    assert result.position_rms < 0.02
    assert result.saturated_fraction == 0.0


def test_meta_records_hidden_effects_apart_from_model_effects(firefly, tmp_path):
    """truth.effects lists each hidden effect with its parameters and hidden: true."""
    effects = [_effect("wind:x=2"), _effect("motor_lag:tau=0.04")]
    Simulator(firefly, effects=effects).run(_hover(1.0), tmp_path / "f")
    meta = read_meta(tmp_path / "f" / "meta.json")
    assert meta["truth"]["effects"] == [
        {"name": "wind", "parameters": {"x": 2.0, "y": 0.0}, "hidden": True},
        {"name": "motor_lag", "parameters": {"tau": 0.04}, "hidden": True}]
    assert meta["model_effects"] == []


def test_config_effects_are_simulated_as_known_physics(firefly, tmp_path):
    """A config's [effects] act on the truth like hidden ones, recorded as model_effects."""
    import dataclasses

    from mavsysid.vehicle.model_effects import MarkerOffset

    config = dataclasses.replace(firefly, effects=(MarkerOffset(z=0.05),))
    result = Simulator(config, settings=_QUIET).run(_hover(1.0), tmp_path / "f")
    pose = read_pose_log(tmp_path / "f" / "pose.csv", firefly.rotor_count)
    np.testing.assert_allclose(pose.position - result.states[:, POS],
                               np.tile([0.0, 0.0, 0.05], (len(pose), 1)), atol=2e-6)
    meta = read_meta(tmp_path / "f" / "meta.json")
    assert meta["model_effects"] == [
        {"name": "marker_offset", "parameters": {"x": 0.0, "y": 0.0, "z": 0.05},
         "hidden": False}]
    assert meta["truth"]["effects"] == []
    assert "[effects.marker_offset]" in meta["vehicle"]["config_toml"]
