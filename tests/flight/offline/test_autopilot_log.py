"""A simulated flight written as ArduPilot and PX4 log it, read back and estimated.

One seeded micro-quad flight (take-off, the built-in excitation as the calibration part,
landing) is written as a ``.bin`` and a ``.ulg`` in each autopilot's motor numbering
(`mavsysid.vehicle.motor_order`), then read with the estimator's readers and estimated.
The vehicle file names its autopilot frame; its rotors spin as that frame's do.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.flight.offline.ardupilot_log import write_ardupilot_log
from mavsysid.flight.offline.autopilot_log import LoggedFlight
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.phased_flight import phased_trajectory
from mavsysid.flight.offline.px4_log import write_px4_log
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.vehicle.config import PARAMETER_NAMES, VehicleConfig, load_vehicle
from mavsysid.vehicle.config_toml import vehicle_to_toml
from mavsysid.vehicle.motor_order import output_to_rotor

from mavsysid.cli.main import main as cli_main

_SHIPPED = Path(__file__).resolve().parents[3] / "vehicle" / "configs" / "micro_quad.toml"
_BOOT = 30.0  # s, the writers' default boot time before the flight


def _vehicle(directory: Path, frame: str) -> tuple[Path, VehicleConfig]:
    """micro_quad with the spin directions of an X quad of both autopilots, naming ``frame``.

    The shipped file spins its front-left rotor counter-clockwise; ArduPilot's and PX4's
    quad X spin it clockwise, so the directions are mirrored (the physics is the same).
    """
    text = _SHIPPED.read_text(encoding="utf-8")
    text = (text.replace("direction = +1", "direction = PLUS").replace("direction = -1",
                                                                       "direction = +1")
            .replace("direction = PLUS", "direction = -1"))
    path = directory / f"micro_quad_{frame.split(':')[0]}.toml"
    path.write_text(text + f'\n[autopilot]\nframe = "{frame}"\n', encoding="utf-8")
    return path, load_vehicle(str(path))


def _prior_file(vehicle: VehicleConfig, path: Path, seed: int) -> Path:
    """The vehicle with a wrong nominal θ (seeded): c_T, c_D, c_M each and J as a whole
    off by up to 25 %, the estimator's prior."""
    rng = np.random.default_rng(seed)
    factors = np.concatenate([rng.uniform(0.75, 1.25, 3), np.full(3, rng.uniform(0.75, 1.25))])
    text = vehicle_to_toml(vehicle.with_parameters(vehicle.theta * factors))
    if "[autopilot]" not in text:
        text += f'\n[autopilot]\nframe = "{vehicle.autopilot_frame}"\n'
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The flight, both logs and both vehicle files."""
    root = tmp_path_factory.mktemp("autopilot_logs")
    _, ap_vehicle = _vehicle(root, "ardupilot:quad_x")
    _, px4_vehicle = _vehicle(root, "px4:quad_x")
    calibration = excitation_trajectory(ExcitationSpec(duration=40.0))
    trajectory, phases = phased_trajectory(calibration)
    Simulator(ap_vehicle, settings=SimulationSettings(seed=7)).run(trajectory, root / "flight")
    flight = LoggedFlight.from_flight_dir(root / "flight", ap_vehicle.rotor_count, phases)
    ap_order = output_to_rotor(ap_vehicle.rotor_positions, ap_vehicle.rotor_directions,
                               "ardupilot:quad_x")
    px4_order = output_to_rotor(px4_vehicle.rotor_positions, px4_vehicle.rotor_directions,
                                "px4:quad_x")
    return {
        "flight": flight, "root": root,
        "bin": (write_ardupilot_log(root / "flight.bin", flight, ap_vehicle, ap_order,
                                    parameters={"FRAME_CLASS": 1, "FRAME_TYPE": 1}),
                _prior_file(ap_vehicle, root / "prior_ardupilot.toml", 1), ap_vehicle, ap_order),
        "ulg": (write_px4_log(root / "flight.ulg", flight, px4_vehicle.limits.rotor_speed_max,
                              px4_order), _prior_file(px4_vehicle, root / "prior_px4.toml", 2),
                px4_vehicle, px4_order),
        "truth": json.loads((root / "flight" / "meta.json").read_text())["truth"]["parameters"],
    }


def _interpolated(t: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t, times, v) for v in values.T])


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["bin", "ulg"])
def test_logs_are_written_in_the_autopilot_numbering(logs, kind):
    """The raw log holds motor i + 1 of the autopilot as ESC i, not config rotor i + 1."""
    path, _, vehicle, order = logs[kind]
    flight = logs["flight"]
    assert list(order) != list(range(vehicle.rotor_count))  # the test needs a permutation
    if kind == "bin":
        from pymavlink.DFReader import DFReader_binary
        log = DFReader_binary(str(path))
        messages = list(iter(lambda: log.recv_match(type=["ESC", "MODE"]), None))
        esc = [m for m in messages if m.get_type() == "ESC" and m.Instance == 0]
        t = np.array([m.TimeUS for m in esc]) * 1e-6 - _BOOT
        logged = np.array([m.RPM for m in esc])
        modes = [m.Mode for m in messages if m.get_type() == "MODE"]
        assert modes[-2:] == [4, 9]  # GUIDED, then LAND
    else:
        from pyulog import ULog
        data = {d.name: d.data for d in ULog(str(path)).data_list}
        t = data["esc_status"]["timestamp"] * 1e-6 - _BOOT
        logged = data["esc_status"]["esc[0].esc_rpm"].astype(float)
        assert list(np.unique(data["vehicle_status"]["nav_state"])) == [2, 14, 18]
    speeds = flight.rotor_speeds * 60.0 / (2.0 * np.pi)
    errors = [np.abs(logged - np.interp(t, flight.t, speeds[:, j])).mean()
              for j in range(vehicle.rotor_count)]
    assert int(np.argmin(errors)) == order[0], errors


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["bin", "ulg"])
def test_readers_give_the_rotors_back_in_config_order(logs, kind):
    """load_flight with the frame-naming vehicle: rotor speeds and pose as flown."""
    path, _, vehicle, _ = logs[kind]
    flight = logs["flight"]
    data = load_flight(path, vehicle)
    t = data.t - _BOOT
    expected = _interpolated(t, flight.t, flight.rotor_speeds)
    deviation = data.rotor_speeds - data.rotor_speeds.mean(axis=1, keepdims=True)
    truth_dev = expected - expected.mean(axis=1, keepdims=True)
    # Per-rotor differences from the mean identify the rotor; absolute speeds alone barely
    # differ between the rotors of a hovering quad.
    for j in range(vehicle.rotor_count):
        assert np.corrcoef(deviation[:, j], truth_dev[:, j])[0, 1] > 0.8, j
    np.testing.assert_allclose(data.position, _interpolated(t, flight.t, flight.position),
                               atol=1e-3)


def _estimate(kind: str, logs: dict, *window: str) -> dict:
    path, vehicle_path, _, _ = logs[kind]
    out = logs["root"] / f"{kind}{len(window)}.json"
    assert cli_main(["estimate", str(path), "--vehicle", str(vehicle_path), "-o", str(out),
                     *window]) == 0
    return json.loads(out.read_text())["parameters"]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["bin", "ulg"])
def test_default_window_estimate_is_within_two_percent(logs, kind):
    """The acceptance check: θ within 2 % of the truth with the default window (the
    GUIDED/OFFBOARD span), from a prior up to 25 % off."""
    estimate = _estimate(kind, logs)
    truth = logs["truth"]
    errors = {p: (estimate[p]["value"] - truth[p]) / abs(truth[p]) for p in PARAMETER_NAMES}
    print(f"{kind} errors: " + ", ".join(f"{p} {e:+.2%}" for p, e in errors.items()))  # pytest -s
    assert max(abs(e) for e in errors.values()) < 0.02, errors
