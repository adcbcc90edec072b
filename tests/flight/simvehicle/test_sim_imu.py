"""The simulated vehicle's IMU over MAVLink, as ArduPilot and PX4 send it.

ArduPilot: RAW_IMU (mG, mrad/s), off until asked for, by SET_MESSAGE_INTERVAL or the
RAW_SENSORS stream group. PX4: HIGHRES_IMU (SI) and SCALED_IMU (mG, mrad/s). Resting on
the ground, the accelerometer reads the reaction to gravity: about [0, 0, −9.81] m/s² FRD,
its bias and noise the vehicle file's.
"""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.simvehicle.link import mavlink as M
from mavsysid.formats.tlog import STANDARD_GRAVITY
from mavsysid.vehicle.config import load_vehicle

from tests.support.sim_gcs import running_sim

ACCEPTED = M.MAV_RESULT_ACCEPTED


def _rate(messages: list, stamp: str) -> float:
    t = np.array([getattr(m, stamp) for m in messages], dtype=float)
    scale = 1e-6 if stamp == "time_usec" else 1e-3
    return (t.size - 1) / ((t[-1] - t[0]) * scale)


def _at_rest(gyro: np.ndarray, accel: np.ndarray) -> None:
    """A level vehicle on the ground: −g on z FRD, no rotation, within bias and noise."""
    noise = load_vehicle("firefly").noise
    np.testing.assert_allclose(accel.mean(axis=0), [0.0, 0.0, -9.81],
                               atol=5 * noise.accel_bias_sigma)
    np.testing.assert_allclose(gyro.mean(axis=0), 0.0, atol=5 * noise.gyro_bias_sigma)
    assert accel.std(axis=0) == pytest.approx([noise.accel_sigma] * 3, rel=0.35)
    assert gyro.std(axis=0) == pytest.approx([noise.gyro_sigma] * 3, rel=0.35)


def test_ardupilot_raw_imu_at_the_requested_rate() -> None:
    with running_sim(ekf_delay=0.0, speedup=4.0) as (_, gcs):
        assert not gcs.collect("RAW_IMU", 1.0)  # off until asked for
        assert gcs.set_rate(M.MAVLINK_MSG_ID_RAW_IMU, 200.0) == ACCEPTED
        gcs.collect("RAW_IMU", 0.1)
        raw = gcs.collect("RAW_IMU", 2.0)
        assert _rate(raw, "time_usec") == pytest.approx(200.0, rel=0.01)
        milli = np.array([[m.xgyro, m.ygyro, m.zgyro, m.xacc, m.yacc, m.zacc] for m in raw],
                         dtype=float)
        _at_rest(milli[:, :3] * 1e-3, milli[:, 3:] * 1e-3 * STANDARD_GRAVITY)
        assert all(m.id == 0 for m in raw)
        # The RAW_SENSORS stream group holds it too (REQUEST_DATA_STREAM).
        assert gcs.set_rate(M.MAVLINK_MSG_ID_RAW_IMU, -1.0) == ACCEPTED
        gcs.link.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_RAW_SENSORS, 50, 1)
        gcs.collect("RAW_IMU", 0.2)
        assert _rate(gcs.collect("RAW_IMU", 2.0), "time_usec") == pytest.approx(50.0, rel=0.02)


def test_px4_highres_and_scaled_imu() -> None:
    with running_sim(autopilot=Autopilot.PX4, ekf_delay=0.0, speedup=4.0) as (_, gcs):
        assert gcs.set_rate(M.MAVLINK_MSG_ID_HIGHRES_IMU, 250.0) == ACCEPTED
        assert gcs.set_rate(M.MAVLINK_MSG_ID_SCALED_IMU, 50.0) == ACCEPTED
        gcs.collect(["HIGHRES_IMU", "SCALED_IMU"], 0.1)
        both = gcs.collect(["HIGHRES_IMU", "SCALED_IMU"], 2.0)
        highres = [m for m in both if m.get_type() == "HIGHRES_IMU"]
        scaled = [m for m in both if m.get_type() == "SCALED_IMU"]
        assert _rate(highres, "time_usec") == pytest.approx(250.0, rel=0.01)
        assert _rate(scaled, "time_boot_ms") == pytest.approx(50.0, rel=0.02)
        assert all(m.fields_updated & 0b111111 == 0b111111 for m in highres)
        gyro = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in highres])
        accel = np.array([[m.xacc, m.yacc, m.zacc] for m in highres])
        _at_rest(gyro, accel)
        # The same sensor at the same instant: SCALED_IMU is HIGHRES_IMU in milli-units.
        by_time = {m.time_usec // 1000: m for m in highres}
        pairs = [(by_time[m.time_boot_ms], m) for m in scaled if m.time_boot_ms in by_time]
        assert len(pairs) > 50
        for h, s in pairs:
            assert s.zacc == round(h.zacc * 1000.0 / STANDARD_GRAVITY)
            assert s.xgyro == round(h.xgyro * 1000.0)
