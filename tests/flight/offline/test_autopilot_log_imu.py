"""The IMU of a simulated flight written as ArduPilot and PX4 log it, and read back.

ArduPilot logs its IMU message after its 2-pole low-pass (INS_GYRO_FILTER,
INS_ACCEL_FILTER), at 25 Hz or 400 Hz (IMU_FAST); PX4 logs sensor_combined at
IMU_INTEG_RATE without a low-pass. Both state the IMU's position (INS_POS1_*,
EKF2_IMU_POS_*, body FRD).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.offline.ardupilot_log import ArduPilotLogSettings, write_ardupilot_log
from mavsysid.flight.offline.autopilot_log import LoggedFlight, lowpass
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.offline.phased_flight import phased_trajectory
from mavsysid.flight.offline.px4_log import PX4LogSettings, write_px4_log
from mavsysid.flight.offline.simulator import SimulationSettings, Simulator
from mavsysid.formats.dataflash import read_dataflash
from mavsysid.formats.ulog import read_ulog
from mavsysid.vehicle.config import VehicleConfig, load_vehicle
from mavsysid.vehicle.frames import flu_to_frd

_BOOT = 30.0  # s, the writers' default boot time before the flight
_LEVER = (0.05, 0.02, -0.01)  # m, body FLU


@pytest.fixture(scope="module")
def quad() -> VehicleConfig:
    return load_vehicle("quad_x")


@pytest.fixture(scope="module")
def flight(quad: VehicleConfig, tmp_path_factory: pytest.TempPathFactory) -> LoggedFlight:
    """A short phased flight at 500 Hz with an offset IMU."""
    root = tmp_path_factory.mktemp("ap_imu")
    calibration = excitation_trajectory(ExcitationSpec(duration=4.0, ramp=1.5))
    trajectory, phases = phased_trajectory(calibration, climb_time=1.5, hover_time=0.5)
    Simulator(quad, settings=SimulationSettings(log_rate=500.0, seed=2, imu_position=_LEVER)
              ).run(trajectory, root / "flight")
    return LoggedFlight.from_flight_dir(root / "flight", quad.rotor_count, phases)


def _at(t: np.ndarray, flight_t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (FLU) at the logged times ``t`` (s since boot), in FRD."""
    i = np.searchsorted(flight_t, t - _BOOT - 1e-7)
    return flu_to_frd(values[i])


@pytest.mark.parametrize("rate", [25.0, 400.0])
def test_ardupilot_imu_is_filtered_and_at_its_rate(flight: LoggedFlight, quad: VehicleConfig,
                                                   tmp_path: Path, rate: float) -> None:
    path = write_ardupilot_log(tmp_path / "f.bin", flight, quad, [0, 1, 2, 3],
                               ArduPilotLogSettings(imu_rate=rate))
    log = read_dataflash(path, quad)
    t = log.gyro.t
    assert (t.size - 1) / (t[-1] - t[0]) == pytest.approx(rate, rel=0.02)
    assert log.imu_filter.gyro_cutoff_hz == 20.0 and log.imu_filter.accel_cutoff_hz == 20.0
    assert log.imu_position == pytest.approx(tuple(flu_to_frd(np.array(_LEVER))), abs=1e-7)
    filtered = lowpass(flight.t, flight.gyro, 20.0)
    np.testing.assert_allclose(log.gyro.values, _at(log.gyro.t, flight.t, filtered), atol=1e-5)
    accel = _at(log.accel.t, flight.t, lowpass(flight.t, flight.accel, 20.0))
    np.testing.assert_allclose(log.accel.values, accel, atol=1e-4)
    assert np.mean(log.accel.values[:, 2]) < -5.0  # FRD: thrust reads along −z
    # The filter's delay is there: the raw samples fit worse than the filtered ones.
    raw = _at(log.gyro.t, flight.t, flight.gyro)
    assert np.abs(log.gyro.values - raw).mean() > 10 * np.abs(
        log.gyro.values - _at(log.gyro.t, flight.t, filtered)).mean()


def test_ardupilot_without_filter_logs_the_samples(flight: LoggedFlight, quad: VehicleConfig,
                                                   tmp_path: Path) -> None:
    settings = ArduPilotLogSettings(imu_rate=400.0, gyro_filter_hz=0.0, accel_filter_hz=0.0)
    log = read_dataflash(write_ardupilot_log(tmp_path / "f.bin", flight, quad, [0, 1, 2, 3],
                                             settings), quad)
    assert log.imu_filter.gyro_cutoff_hz == 0.0
    np.testing.assert_allclose(log.gyro.values, _at(log.gyro.t, flight.t, flight.gyro),
                               atol=1e-6)


def test_px4_sensor_combined_at_the_integration_rate(flight: LoggedFlight,
                                                     quad: VehicleConfig, tmp_path: Path) -> None:
    path = write_px4_log(tmp_path / "f.ulg", flight, quad.limits.rotor_speed_max, [0, 1, 2, 3],
                         PX4LogSettings(imu_rate=250.0))
    log = read_ulog(path, quad)
    assert log.gyro.label.startswith("sensor_combined")
    t = log.gyro.t
    assert (t.size - 1) / (t[-1] - t[0]) == pytest.approx(250.0, rel=0.02)
    np.testing.assert_allclose(log.gyro.values, _at(log.gyro.t, flight.t, flight.gyro),
                               atol=1e-5)
    np.testing.assert_allclose(log.accel.values, _at(log.accel.t, flight.t, flight.accel),
                               atol=1e-4)
    assert log.imu_filter.gyro_cutoff_hz == 0.0
    assert log.imu_position == pytest.approx(tuple(flu_to_frd(np.array(_LEVER))), abs=1e-7)


def test_a_flight_without_imu_writes_none(flight: LoggedFlight, quad: VehicleConfig,
                                          tmp_path: Path) -> None:
    from dataclasses import replace

    bare = replace(flight, gyro=None, accel=None, imu_position=None)
    log = read_dataflash(write_ardupilot_log(tmp_path / "f.bin", bare, quad, [0, 1, 2, 3]),
                         quad)
    assert log.gyro is None and log.imu_filter is None and log.imu_position is None
    log = read_ulog(write_px4_log(tmp_path / "f.ulg", bare, quad.limits.rotor_speed_max,
                                  [0, 1, 2, 3]), quad)
    assert log.gyro is None and log.imu_position is None
