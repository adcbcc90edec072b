"""Downloading the flight's own log over MAVLink from `mavsysid sim`, over UDP loopback.

The simulated vehicle logs while armed and serves its logs over the log protocol as
ArduPilot does; the download must give back the very bytes it built, also when LOG_DATA
messages are lost on the way (the gaps are asked for again).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.log_download import CHUNK, download_latest_log, log_file_name
from mavsysid.formats.dataflash import read_dataflash
from mavsysid.formats.ulog import read_ulog
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import JobFailedError
from tests.support.sim_link import linked_sim


def _fly_on_the_ground(endpoint, link, seconds: float) -> None:
    """Arm, idle ``seconds`` (link s), disarm: one log."""
    endpoint.call_soon(lambda: endpoint.autopilot.arm(True))
    link.poll(seconds)
    endpoint.call_soon(lambda: endpoint.autopilot.arm(False))
    link.poll(0.5)
    assert not endpoint.autopilot.armed


@pytest.mark.parametrize(("autopilot", "suffix"), [(Autopilot.ARDUPILOT, ".bin"),
                                                   (Autopilot.PX4, ".ulg")])
def test_download_gives_the_vehicles_log(tmp_path: Path, autopilot: Autopilot,
                                         suffix: str) -> None:
    with linked_sim(autopilot, speedup=2.0, ekf_delay=0.0) as (endpoint, link):
        _fly_on_the_ground(endpoint, link, 1.0)
        _fly_on_the_ground(endpoint, link, 2.0)  # the newest: the one downloaded
        download = download_latest_log(link, tmp_path)
        (first, newest) = endpoint.onboard_log.finished()
        expected = endpoint.onboard_log.data(newest)
    assert download.log_id == 2 and download.complete
    assert download.path.name == f"autopilot{suffix}"
    assert download.path.read_bytes() == expected
    assert download.size == len(expected) > len(endpoint.onboard_log.data(first))
    log = (read_dataflash if suffix == ".bin" else read_ulog)(download.path,
                                                             load_vehicle("firefly"))
    # Idling on the ground: the IMU reads the reaction to gravity, −g on z FRD.
    assert np.mean(log.accel.values[:, 2]) == pytest.approx(-9.81, abs=0.5)
    assert log.gyro.t[-1] - log.gyro.t[0] == pytest.approx(2.0, abs=0.1)
    summary = download.summary()
    assert summary["complete"] and summary["bytes_per_s"] > 0


def test_lost_log_data_is_asked_for_again(tmp_path: Path) -> None:
    """Every 7th chunk of the first pass is dropped on the way: the downloader asks for
    each missing stretch again and ends with every byte."""
    with linked_sim(Autopilot.ARDUPILOT, speedup=2.0, ekf_delay=0.0) as (endpoint, link):
        _fly_on_the_ground(endpoint, link, 1.0)
        service, dropped = endpoint.log_service, set()
        original = service.due

        def lossy():
            for msg in original():
                if msg.ofs // CHUNK % 7 == 3 and msg.ofs not in dropped:
                    dropped.add(msg.ofs)
                    continue
                yield msg

        service.due = lossy
        download = download_latest_log(link, tmp_path)
        expected = endpoint.onboard_log.data(endpoint.onboard_log.finished()[0])
    assert len(dropped) > 10
    assert download.complete and download.path.read_bytes() == expected
    assert download.requests > 1


def test_a_vehicle_without_logs_says_so(tmp_path: Path) -> None:
    with linked_sim(Autopilot.ARDUPILOT, speedup=2.0, ekf_delay=0.0) as (_, link), \
            pytest.raises(JobFailedError, match="lists no logs"):
        download_latest_log(link, tmp_path)
    assert not list(tmp_path.iterdir())


def test_file_names_follow_the_format() -> None:
    assert log_file_name(b"\xa3\x95\x80rest") == "autopilot.bin"
    assert log_file_name(b"ULog\x01\x12\x35\x01") == "autopilot.ulg"
    assert log_file_name(b"junk") == "autopilot.log"
