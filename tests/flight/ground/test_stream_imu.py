"""A streamed flight records the vehicle's IMU and downloads the vehicle's own log.

`mavsysid stream` against `mavsysid sim` (two processes, UDP loopback, lock-step): the IMU
asked for at the rate the link carries lands in pose.csv (FLU) as the simulator's truth
plus the vehicle's IMU bias and noise; after landing the vehicle's DataFlash log is
downloaded over MAVLink into the flight directory, with its IMU at 400 Hz (LOG_BITMASK
IMU_FAST for the flight, restored after). About 50 s.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.formats.dataflash import read_dataflash
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.config import load_vehicle

from tests.support.stream_flights import SimProcess, export_excitation, flight_dir, run_stream

pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore::UserWarning")]


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> dict:
    tmp = tmp_path_factory.mktemp("imu_stream")
    trajectory = export_excitation(tmp / "excitation.json", 10.0)
    port = free_udp_port()
    with SimProcess(tmp / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup", "4",
                    "--truth-log", str(tmp / "truth")) as sim:
        result = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup",
                            "4", "--log-dir", str(tmp / "logs"), cwd=tmp)
        sim.stop()
    directory = flight_dir(tmp / "logs")
    return {"result": result, "dir": directory, "truth": tmp / "truth",
            "meta": read_meta(directory / "meta.json")}


def test_pose_log_holds_the_vehicles_imu(flight: dict) -> None:
    assert flight["result"].returncode == 0, flight["result"].stderr
    meta = flight["meta"]
    assert meta["imu"]["message"] == "RAW_IMU" and meta["imu"]["in_pose_csv"]
    assert meta["imu"]["preflight_hz"] == pytest.approx(250.0, rel=0.02)  # the sim's cap
    pose = read_pose_log(flight["dir"] / "pose.csv", 6)
    truth = read_pose_log(flight["truth"] / "truth.csv", 6)
    imu = json.loads((flight["truth"] / "meta.json").read_text())["truth"]["imu"]
    i = np.clip(np.searchsorted(truth.t, pose.t - 1e-7), 0, len(truth) - 1)
    same = np.abs(truth.t[i] - pose.t) < 1e-6  # rows at the truth's 5 ms instants
    assert same.sum() > 400
    config = load_vehicle("firefly")
    for measured, true, bias, sigma in (
            (pose.gyro, truth.gyro, imu["gyro_bias_rad_s"], config.noise.gyro_sigma),
            (pose.accel, truth.accel, imu["accel_bias_m_s2"], config.noise.accel_sigma)):
        error = measured[same] - true[i[same]]
        # RAW_IMU's mG and mrad/s add their rounding to the noise.
        np.testing.assert_allclose(error.mean(axis=0), bias, atol=5 * sigma / np.sqrt(same.sum()))
        np.testing.assert_allclose(error.std(axis=0), sigma, rtol=0.15)
    airborne = pose.position[:, 2] > 0.5
    assert np.mean(pose.accel[airborne, 2]) == pytest.approx(9.81, rel=0.05)


def test_the_vehicles_own_log_is_downloaded(flight: dict) -> None:
    meta = flight["meta"]
    record = meta["autopilot_log"]
    assert record["complete"] and meta["files"]["autopilot_log"] == "autopilot.bin"
    assert "downloaded the vehicle's log 1" in flight["result"].stderr
    log = read_dataflash(flight["dir"] / "autopilot.bin", load_vehicle("firefly"))
    t = log.gyro.t
    assert (t.size - 1) / (t[-1] - t[0]) == pytest.approx(400.0, rel=0.01)
    assert log.imu_filter.gyro_cutoff_hz == 20.0
    assert log.motor_outputs is not None and len(log.esc_speeds) == 6
    # LOG_BITMASK: IMU_FAST for the flight, put back after it.
    changed = meta["parameters"]["LOG_BITMASK"]
    assert changed["restored"] and int(changed["flight"]) == int(changed["original"]) | 1 << 18
