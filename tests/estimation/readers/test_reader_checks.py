"""Bad inputs to load_flight: one-line errors naming the file, and repairs with counts."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.readers.samples import MAX_GAP, check_sampling
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import InputError, LogFormatError

Truth = Callable[[np.ndarray], dict[str, np.ndarray]]
Rows = dict[str, list[dict[str, float]]]
ODOMETRY = "vehicle_mocap_odometry"


def _error(path: Path, vehicle: VehicleConfig, **kwargs: object) -> str:
    with pytest.raises(InputError) as info:
        load_flight(path, vehicle, **kwargs)  # type: ignore[arg-type]
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    return message


@pytest.mark.parametrize(("name", "content", "says"), [
    ("flight.txt", b"t,x\n", "unsupported flight log type '.txt'"),
    ("flight.tlog", bytes(range(256)) * 4, "no MAVLink messages"),
    ("flight.ulg", b"not a ulog file at all" * 10, "cannot be read as a PX4 ULog file"),
    ("flight.BIN", bytes(range(256)) * 4, "no rotor speeds or motor outputs"),
])
def test_unreadable_file_is_one_line(tmp_path: Path, firefly: VehicleConfig, name: str,
                                     content: bytes, says: str) -> None:
    """A file of the wrong type or content fails in one line naming it, no traceback text."""
    path = tmp_path / name
    path.write_bytes(content)
    message = _error(path, firefly)
    assert says in message and "Traceback" not in message


def test_missing_file_and_stray_offset_are_input_errors(tmp_path: Path,
                                                        firefly: VehicleConfig) -> None:
    """A missing log, or a time offset without a pose file, is an InputError (exit 2)."""
    assert "no such file" in _error(tmp_path / "absent.ulg", firefly)
    path = tmp_path / "flight.ulg"
    path.write_bytes(b"x")
    assert "time offset" in _error(path, firefly, time_offset=1.0)


def _drop_window(t0: float, t1: float, topic: str = ODOMETRY) -> Callable[[Rows], None]:
    def edit(topics: Rows) -> None:
        topics[topic] = [r for r in topics[topic]
                         if not t0 * 1e6 < r.get("timestamp_sample", r["timestamp"]) < t1 * 1e6]
    return edit


def _scale_quaternions(rows: slice, factor: float) -> Callable[[Rows], None]:
    def edit(topics: Rows) -> None:
        for r in topics[ODOMETRY][rows]:
            for i in range(4):
                r[f"q[{i}]"] *= factor
    return edit


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"esc_count": 4}, "rotor speeds of 4 rotors, the vehicle config builtin:firefly has 6"),
    ({"duration": 1.5}, "only 1.47 s of pose and rotor speeds"),
    ({"edit": _scale_quaternions(slice(40, 42), 1.5)}, "2 attitude quaternions of"),
    ({"pose": None}, "no pose in the log (no vehicle_mocap_odometry"),
])
def test_unusable_flight_is_one_line_error(tmp_path: Path, firefly: VehicleConfig,
                                           truth: Truth, ulog_writer: Callable[..., Path],
                                           kwargs: dict[str, object], says: str) -> None:
    """Each unusable flight fails with a LogFormatError naming the file and the problem."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, **kwargs)
    with pytest.raises(LogFormatError):
        load_flight(path, firefly)
    assert says in _error(path, firefly)


def _nan_rows(topics: Rows) -> None:
    for r in topics[ODOMETRY][100:103]:
        r["position[1]"] = np.nan


def _shuffle_and_repeat(topics: Rows) -> None:
    rows = topics[ODOMETRY]
    rows[10], rows[11] = rows[11], rows[10]
    rows[50], rows[51] = rows[51], rows[50]
    rows.insert(200, dict(rows[200]))


@pytest.mark.parametrize(("edit", "says"), [
    (_nan_rows, "dropped 3 rows of vehicle_mocap_odometry samples with NaN or infinite "
                "values (of 400)"),
    (_shuffle_and_repeat, "2 timestamps of vehicle_mocap_odometry samples out of order"),
    (_shuffle_and_repeat, "dropped 1 sample of vehicle_mocap_odometry with a duplicate"),
    (_drop_window(21.0, 21.05), "1 gap in the pose samples longer than 2 sample periods "
                                "(0.02 s), longest 0.05 s after t = 21.000 s"),
    (_scale_quaternions(slice(40, 44), 1.01), "normalised 4 attitude quaternions of "
                                              "vehicle_mocap_odometry"),
])
def test_repairable_flight_warns_with_counts(tmp_path: Path, firefly: VehicleConfig,
                                             truth: Truth, ulog_writer: Callable[..., Path],
                                             assert_matches_truth: Callable[..., None],
                                             edit: Callable[[Rows], None], says: str) -> None:
    """Repairable problems are repaired, the data stay right, and a warning counts them."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, edit=edit)
    data = load_flight(path, firefly)
    assert [w for w in data.warnings if says in w] != [], data.warnings
    assert all(w.startswith(f"{path}: ") and "\n" not in w for w in data.warnings)
    assert (np.diff(data.t) > 0).all()
    assert_matches_truth(data, truth, 0.1)


@pytest.mark.parametrize(("edit", "gap"), [
    (_drop_window(23.0, 23.5), (23.0, 23.5)),
    (_drop_window(24.0, 24.4, "esc_status"), (23.987, 24.407)),
])
def test_long_gap_splits_the_flight(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                                    ulog_writer: Callable[..., Path],
                                    assert_matches_truth: Callable[..., None],
                                    edit: Callable[[Rows], None],
                                    gap: tuple[float, float]) -> None:
    """A gap (in the pose or in the rotor speeds) too long to bridge splits the flight in two
    segments, with no sample inside the gap and a note saying so."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, duration=8.0, edit=edit)
    data = load_flight(path, firefly)
    assert len(data.segment_starts) == 2, data.warnings
    second = data.segment_starts[1]
    assert data.t[second - 1] <= gap[0] + 1e-9 and data.t[second] >= gap[1] - 1e-9
    assert not ((data.t > gap[0] + 1e-9) & (data.t < gap[1] - 1e-9)).any()
    assert [w for w in data.warnings if "split the flight into 2 segments" in w], data.warnings
    assert_matches_truth(data, truth, 0.1)


def test_gap_of_exactly_the_limit_is_bridged(tmp_path: Path, firefly: VehicleConfig,
                                             truth: Truth,
                                             ulog_writer: Callable[..., Path]) -> None:
    """A 0.2 s gap (µs timestamps, floats) is not "more than 0.2 s": one segment."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, edit=_drop_window(20.01, 20.21))
    data = load_flight(path, firefly)
    assert data.segment_starts == (0,)
    step = np.diff(data.t)
    # In floats this gap is 0.2000000000000028 s: "more than 0.2 s" to an exact comparison.
    assert 0.2 < step.max() < 0.2 + 1e-9


def test_short_segment_is_dropped(tmp_path: Path, firefly: VehicleConfig, truth: Truth,
                                  ulog_writer: Callable[..., Path]) -> None:
    """A segment shorter than the minimum duration is dropped, with a note."""
    path = ulog_writer(tmp_path / "flight.ulg", truth, firefly, edit=_drop_window(21.0, 21.5))
    data = load_flight(path, firefly)
    assert data.segment_starts == (0,) and data.t[0] >= 21.5
    assert [w for w in data.warnings if "dropped the segment t = 20.0" in w and
            "to 21.000 s, shorter than 2 s" in w], data.warnings


@pytest.mark.parametrize("period", [0.25, 0.5])
def test_slow_sampling_is_noted_not_refused(period: float) -> None:
    """A series slower than every MAX_GAP is information too: one note, no error."""
    rng = np.random.default_rng(5)
    t = np.cumsum(np.full(40, period) + rng.uniform(-0.01, 0.01, 40))
    notes = check_sampling(t, "log.ulg", "esc_status rpm")
    assert period > MAX_GAP
    assert notes == [f"log.ulg: esc_status rpm sampled only every {np.median(np.diff(t)):.3g} s "
                     f"(slower than every {MAX_GAP:g} s): used, with the larger uncertainty "
                     "that leaves between samples"]
    assert check_sampling(t * (0.1 / period), "log.ulg", "esc_status rpm") == []
