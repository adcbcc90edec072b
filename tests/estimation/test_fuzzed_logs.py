"""Fuzzed flight logs of every format (issue 19): no traceback, no hang, no wrong θ at exit 0.

A short clean simulated flight is written as pose.csv, .tlog, .ulg and .bin and mutated in
its values and bytes (`tests.support.log_fuzz`). The readers must return a flight or
refuse in one line (`LogFormatError`/`InputError`), within a time bound, without output of
their own; huge files are refused before parsing and a stuck parser is stopped
(`mavsysid.estimation.readers.guard`). On a seeded sample the whole estimate runs: it must
exit 0 within 50 % of the truth (the clean log estimates within 1 %) or refuse. The full
≥ 1000-log run is ``bench/fuzz_logs.py``.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mavsysid.estimation.readers import guard, load_flight
from mavsysid.vehicle.config import load_vehicle

from mavsysid.errors import InputError, LogFormatError
from tests.support.fuzz_run import estimate_outcome, fuzz_plan
from tests.support.log_fuzz import FORMATS, CleanFlight, clean_flight, fuzz_case

#: s a fuzzed log of a few seconds may take to be read or refused: far above the
#: clean read (< 1 s), far below a hang.
_READ_SECONDS = 20.0


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> CleanFlight:
    """8 s of the built-in excitation, Firefly, seeded."""
    return clean_flight(load_vehicle("firefly"), tmp_path_factory.mktemp("clean") / "f", seed=1)


def _read_or_refuse(path: Path) -> str:
    """``"ok"`` or the refusal's type; any other exception fails the test (a traceback)."""
    try:
        load_flight(path, load_vehicle("firefly"))
    except (LogFormatError, InputError) as exc:
        message = str(exc)
        assert "\n" not in message and str(path) in message, message
        return type(exc).__name__
    return "ok"


@pytest.mark.slow
def test_fuzzed_logs_are_read_or_refused_in_one_line(
        flight: CleanFlight, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """100 seeded value and byte mutations over the four formats, at the reader level."""
    outcomes = []
    for i, (suffix, value, byte, seed) in enumerate(fuzz_plan(100, seed=7)):
        case = fuzz_case(tmp_path / f"c{i}", flight, suffix, value, byte, seed, 3 * 1024**3)
        start = time.perf_counter()
        outcomes.append(_read_or_refuse(case.path))
        assert time.perf_counter() - start < _READ_SECONDS, case
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out[-500:], err[-500:])  # parsers' noise swallowed
    # The mix exercised both paths (not a vacuous pass).
    assert 0 < outcomes.count("ok") < len(outcomes)


@pytest.mark.parametrize("suffix", FORMATS)
def test_huge_file_is_refused_before_parsing(flight: CleanFlight, tmp_path: Path,
                                             suffix: str) -> None:
    case = fuzz_case(tmp_path, flight, suffix, "none", "huge", 0, guard.MAX_LOG_BYTES + 1)
    start = time.perf_counter()
    with pytest.raises(LogFormatError, match=r"larger than the 2\.15 GB a flight log may have"):
        load_flight(case.path, load_vehicle("firefly"))
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize("suffix", [".tlog", ".bin", ".ulg"])
def test_stuck_parser_is_stopped_in_one_line(flight: CleanFlight, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             suffix: str) -> None:
    """A parse over its time budget (made tiny here) ends in one line, not a hang."""
    case = fuzz_case(tmp_path, flight, suffix, "none", "junk_tail", 3)
    monkeypatch.setattr(guard, "PARSE_SECONDS", 1e-4)
    monkeypatch.setattr(guard, "PARSE_SECONDS_PER_MB", 0.0)
    with pytest.raises(LogFormatError, match=r"parsing took longer than 0 s \(corrupt data\?\)"):
        load_flight(case.path, load_vehicle("firefly"))


def test_parser_output_below_python_is_silenced(flight: CleanFlight, tmp_path: Path,
                                                capfd: pytest.CaptureFixture[str]) -> None:
    """pymavlink's compiled DataFlash indexer writes to descriptor 2 on junk: not shown."""
    case = fuzz_case(tmp_path, flight, ".bin", "none", "junk", 2)
    _read_or_refuse(case.path)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


@pytest.fixture(scope="module")
def clean_errors(flight: CleanFlight, tmp_path_factory: pytest.TempPathFactory
                 ) -> dict[str, float]:
    """Each format's clean log: the largest relative θ error of its estimate."""
    root = tmp_path_factory.mktemp("clean_logs")
    theta = load_vehicle("firefly").theta
    errors = {}
    for suffix in FORMATS:
        outcome = estimate_outcome(fuzz_case(root / suffix[1:], flight, suffix, "none", "none",
                                             0).path, "firefly", theta)
        assert outcome.kind == "exit0", outcome
        errors[suffix] = outcome.error
    return errors


@pytest.mark.slow
def test_fuzzed_estimates_refuse_rather_than_mislead(
        flight: CleanFlight, clean_errors: dict[str, float], tmp_path: Path) -> None:
    """24 seeded value mutations: exit 0 within 50 % of the truth, or a refusal."""
    assert max(clean_errors.values()) < 0.01  # the premise: clean logs estimate within 1 %
    theta = load_vehicle("firefly").theta
    kinds = []
    for i, (suffix, value, _, seed) in enumerate(fuzz_plan(24, seed=11)):
        case = fuzz_case(tmp_path / f"c{i}", flight, suffix, value, "none", seed)
        outcome = estimate_outcome(case.path, "firefly", theta)
        assert outcome.kind != "traceback", outcome.message
        assert outcome.kind != "exit0" or outcome.error <= 0.5, (case, outcome)
        kinds.append(outcome.kind)
    assert "exit0" in kinds and len(set(kinds)) > 1


@pytest.mark.slow
def test_cli_on_fuzzed_logs_exits_in_one_line(flight: CleanFlight, tmp_path: Path) -> None:
    """The console command on corrupted logs: a documented exit code, and on refusal one
    line on stderr, never a traceback."""
    cases = [fuzz_case(tmp_path / s[1:], flight, s, value, byte, 5)
             for s, value, byte in [(".csv", "nan", "words"), (".bin", "big_1e30", "flip")]]
    for case in cases:
        done = subprocess.run([sys.executable, "-m", "mavsysid", "estimate", str(case.path),
                               "--vehicle", "firefly", "-q"], capture_output=True, text=True,
                              timeout=300)
        assert "Traceback" not in done.stderr and done.returncode in (0, 2, 3), done.stderr
        if done.returncode:
            assert done.stderr.count("\n") == 1 and ": error: " in done.stderr, done.stderr
    assert np.all([c.path.is_file() for c in cases])
