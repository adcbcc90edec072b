"""The calibration window: --start/--end, meta.json's trajectory window, the autopilot's modes."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.readers.logs import longest_span, spans_of
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import InputError

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]
AUTOPILOT = (1, 1)
GUIDED, STABILIZE, LAND = 4, 0, 9  # ArduCopter custom modes
CUSTOM_MODE_ENABLED = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


def _flight(truth: Truth, mode_at: Callable[[float], int]) -> list[Any]:
    """Records of a 10 s flight (t = 10 to 20 s since boot): 1 Hz HEARTBEATs in the mode
    ``mode_at(t)``, pose and ESC rpm at 50 Hz; received 1 ms after sending."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    records: list[Any] = []
    for t in 10.0 + np.arange(11.0):
        beat = m.MAVLink_heartbeat_message(2, 3, CUSTOM_MODE_ENABLED, mode_at(t), 4, 3)
        records.append((t + 0.001, beat, AUTOPILOT))
    t_pos = 10.0 + np.arange(500) / 50.0
    x = truth(t_pos)
    for t, p, q in zip(t_pos, x["position_ned"], x["quaternion_ned"], strict=True):
        records.append((t + 0.001, m.MAVLink_local_position_ned_message(
            round(t * 1e3), *p, 0.0, 0.0, 0.0), AUTOPILOT))
        records.append((t + 0.001, m.MAVLink_attitude_quaternion_message(
            round(t * 1e3), *q, 0.0, 0.0, 0.0, [0.0] * 4), AUTOPILOT))
    t_rot = t_pos + 0.005
    for t, row in zip(t_rot, truth(t_rot)["rotor_speeds"], strict=True):
        rpm = [round(v * 60.0 / (2.0 * np.pi)) for v in row] + [0, 0]
        for cls, part in ((m.MAVLink_esc_telemetry_1_to_4_message, rpm[:4]),
                          (m.MAVLink_esc_telemetry_5_to_8_message, rpm[4:])):
            records.append((t + 0.001, cls([0] * 4, [0] * 4, [0] * 4, [0] * 4, part, [0] * 4),
                            AUTOPILOT))
    return records


def _guided_12_to_17(t: float) -> int:
    return GUIDED if 12.0 <= t <= 17.0 else (STABILIZE if t < 12.0 else LAND)


def test_spans_of_events_and_reports() -> None:
    """Mode changes last until the next change; periodic reports span first to last."""
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    active = np.array([False, True, True, False, True, True])
    assert spans_of(t, active, True, 9.0) == [(1.0, 3.0), (4.0, 9.0)]
    assert spans_of(t, active, False, 9.0) == [(1.0, 2.0), (4.0, 5.0)]
    assert longest_span([(1.0, 3.0), (4.0, 9.0)]) == (4.0, 9.0)
    assert longest_span([]) is None


def test_tlog_default_window_is_the_guided_span(tmp_path: Path, firefly: VehicleConfig,
                                                 truth: Truth,
                                                 tlog_writer: Callable[..., None]) -> None:
    """Without meta.json the window is the GUIDED span of the HEARTBEATs, said in a note;
    ``auto_window=False`` reads the whole log."""
    path = tmp_path / "flight.tlog"
    tlog_writer(path, _flight(truth, _guided_12_to_17))
    data = load_flight(path, firefly)
    assert data.t[0] >= 12.0 - 1e-6 and data.t[-1] <= 17.0 + 1e-6
    assert data.t[0] < 12.03 and data.t[-1] > 16.97
    assert [w for w in data.warnings if w.startswith("info:") and "GUIDED" in w], data.warnings
    whole = load_flight(path, firefly, auto_window=False)
    assert whole.t[0] < 10.03 and whole.t[-1] > 19.95


def test_meta_json_window_and_start_end(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                                        tlog_writer: Callable[..., None]) -> None:
    """The streamer's trajectory window in meta.json beats the modes; --start/--end beat both."""
    path = tmp_path / "flight.tlog"
    tlog_writer(path, _flight(truth, _guided_12_to_17))
    (tmp_path / "meta.json").write_text(json.dumps(
        {"trajectory_window": {"start": 13.0, "end": 16.0}}))
    data = load_flight(path, firefly)
    assert data.t[0] == pytest.approx(13.0, abs=0.021) and data.t[-1] == pytest.approx(
        16.0, abs=0.021)
    assert [w for w in data.warnings if "meta.json trajectory_window" in w], data.warnings
    given = load_flight(path, firefly, start=10.5, end=19.0)
    assert given.t[0] == pytest.approx(10.5, abs=0.021) and given.t[-1] <= 19.0
    assert [w for w in given.warnings if "--start/--end" in w], given.warnings
    with pytest.raises(InputError, match="expected start < end"):
        load_flight(path, firefly, start=15.0, end=14.0)
