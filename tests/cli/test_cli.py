"""Tests of the ``mavsysid`` console script: output, exit codes and error messages."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.poselog import read_pose_log

from mavsysid.cli import main
from mavsysid.cli.main import exit_code
from mavsysid.errors import (
    ConfigError,
    InputError,
    JobFailedError,
    LogFormatError,
    MavsysidError,
)

HERE = Path(__file__).parent
BAD_VEHICLES = HERE.parent / "data" / "bad_vehicles"
EXPECTED_KEYS = json.loads((BAD_VEHICLES / "expected.json").read_text())


def _normalise(text: str, logs: Path) -> str:
    text = text.replace(str(logs), "<LOGS>")
    return re.sub(r"speed      \d+x real time", "speed      <N>x real time", text)


def test_simulate_output_matches_golden(tmp_path, capsys):
    """The summary printed after a simulated flight matches the golden text."""
    code = main(["simulate", "--logs", str(tmp_path), "--name", "golden",
                 "--duration", "12", "--seed", "1"])
    out = capsys.readouterr().out
    assert code == 0
    golden = (HERE / "golden" / "simulate.txt").read_text()
    assert _normalise(out, tmp_path) == golden


def test_quiet_prints_only_the_flight_directory(tmp_path, capsys):
    """-q prints the flight directory alone, so scripts can capture it."""
    assert main(["-q", "simulate", "--logs", str(tmp_path), "--name", "f",
                 "--duration", "10"]) == 0
    assert capsys.readouterr().out == f"{tmp_path / 'f'}\n"
    assert len(read_pose_log(tmp_path / "f" / "pose.csv")) == 1001


@pytest.mark.parametrize("filename", sorted(EXPECTED_KEYS))
def test_malformed_vehicle_file_exits_2_naming_the_key(filename, tmp_path, capsys):
    """Each malformed TOML gives exit code 2 and one stderr line naming the file and key."""
    path = BAD_VEHICLES / filename
    code = main(["simulate", "--vehicle", str(path), "--logs", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.endswith("\n") and err.count("\n") == 1
    assert filename in err
    assert EXPECTED_KEYS[filename] in err
    assert not any(tmp_path.iterdir()), "nothing is written for bad input"


@pytest.mark.parametrize("command", ["demo", "simulate", "estimate", "diagnose", "plan", "sim",
                                     "stream", "evaluate"])
def test_every_command_has_help(command, capsys):
    """--help works on every subcommand and exits 0."""
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: mavsysid" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [[], ["simulate", "--bogus"], ["fly"],
                                  ["simulate", "--duration", "x"]])
def test_usage_errors_exit_2(argv, capsys):
    """Missing or unknown commands and options are usage errors with exit code 2."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2


@pytest.mark.parametrize("option", [["--duration", "4"], ["--physics-rate", "300"],
                                    ["--log-rate", "300"]])
def test_bad_numbers_exit_2_with_one_line(option, tmp_path, capsys):
    """Impossible durations or rates are reported in one line with exit code 2."""
    assert main(["simulate", "--logs", str(tmp_path), *option]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not any(tmp_path.iterdir())


def test_existing_flight_name_is_refused(tmp_path, capsys):
    """A flight is never written over: an existing --name is exit code 2."""
    (tmp_path / "f").mkdir()
    assert main(["simulate", "--logs", str(tmp_path), "--name", "f"]) == 2
    assert "already exists" in capsys.readouterr().err


def _run(args, **kwargs):
    return subprocess.run([sys.executable, "-m", "mavsysid", *args], capture_output=True,
                          text=True, timeout=300, **kwargs)


def test_console_script_reports_version_and_errors_without_traceback(tmp_path):
    """The real entry point prints its version, and bad input never shows a traceback."""
    done = _run(["--version"])
    assert done.returncode == 0 and done.stdout.startswith("mavsysid ")
    done = _run(["simulate", "--vehicle", str(BAD_VEHICLES / "missing_mass.toml"),
                 "--logs", str(tmp_path)])
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1


@pytest.mark.slow
def _rows_written(path: Path) -> int:
    """Complete lines in a log being written (0 before it exists)."""
    return path.read_bytes().count(b"\n") if path.exists() else 0


def test_interrupt_exits_130_and_keeps_the_log(tmp_path):
    """Ctrl-C mid-flight exits 130, leaving a readable pose log and meta status 'aborted'."""
    flight = tmp_path / "long"
    proc = subprocess.Popen(
        [sys.executable, "-m", "mavsysid", "simulate", "--logs", str(tmp_path),
         "--name", "long", "--duration", "3000"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # A shell's background job inherits SIGINT ignored; Ctrl-C is what is tested.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    # A wait, not a bound: a fresh clone compiles the kernels first, slowly on a busy machine.
    deadline = time.monotonic() + 600
    pose = flight / "pose.csv"
    while time.monotonic() < deadline and _rows_written(pose) < 150:
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert err == "mavsysid simulate: interrupted\n"
    log = read_pose_log(pose)
    assert 100 < len(log) < 300001
    assert read_meta(flight / "meta.json")["status"] == "aborted"


def test_vehicle_too_weak_for_the_figure_exits_3(tmp_path, capsys):
    """A valid vehicle whose rotors cannot fly the excitation: exit 3, reason, nothing flown."""
    from dataclasses import replace

    from mavsysid.vehicle.config import load_vehicle, save_vehicle

    cfg = load_vehicle("firefly")
    weak = replace(cfg, limits=replace(cfg.limits, rotor_speed_max=620.0))
    save_vehicle(weak, tmp_path / "weak.toml")
    code = main(["simulate", "--vehicle", str(tmp_path / "weak.toml"),
                 "--logs", str(tmp_path / "logs")])
    err = capsys.readouterr().err
    assert code == 3
    assert "weak.toml" in err and "620" in err and err.count("\n") == 1
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize(("cause", "expected"), [(KeyboardInterrupt, 130), (ValueError, 1)])
def test_interrupt_inside_numba_kernel_exits_130(cause, expected, monkeypatch, capsys):
    """A SystemError chained on Ctrl-C exits 130; any other is an internal error (exit 1)."""
    import mavsysid.cli.evaluate

    def run(args):
        try:
            raise cause
        except cause as inner:
            raise SystemError("returned a result with an exception set") from inner

    monkeypatch.setattr(mavsysid.cli.evaluate, "main", run)
    monkeypatch.delenv("MAVSYSID_DEBUG", raising=False)
    assert main(["evaluate", "--n", "1"]) == expected
    err = capsys.readouterr().err
    if expected == 1:
        assert err.startswith("mavsysid evaluate: internal error: SystemError: ")
        assert err.count("\n") == 1 and "Traceback" not in err
        return
    assert err == "mavsysid evaluate: interrupted\n"


class _LinkGone(JobFailedError):
    """A subclass elsewhere in the code (like the ground station's HeartbeatLost)."""


@pytest.mark.parametrize(("error", "expected"), [
    (MavsysidError("x"), 1), (InputError("x"), 2), (ConfigError("x"), 2),
    (LogFormatError("x"), 2), (JobFailedError("x"), 3), (_LinkGone("x"), 3),
])
def test_error_types_map_to_exit_codes(error, expected, monkeypatch, capsys):
    """The CLI's table gives each error type its exit code and prints one line."""
    import mavsysid.cli.evaluate

    def run(args):
        raise error

    assert exit_code(error) == expected
    monkeypatch.setattr(mavsysid.cli.evaluate, "main", run)
    assert main(["evaluate", "--n", "1"]) == expected
    assert capsys.readouterr().err == "mavsysid evaluate: error: x\n"


@pytest.mark.parametrize("command", ["sim", "stream"])
def test_vehicle_side_commands_do_not_import_the_estimation_stack(command):
    """`sim` and `stream` start without importing estimation, diagnosis or evaluation."""
    code = ("import sys\nfrom mavsysid.cli import main\n"
            f"try:\n    main(['{command}', '--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.startswith(('mavsysid.estimation', "
            "'mavsysid.discrepancy', 'mavsysid.experiments', 'statsmodels'))))")
    env = {**os.environ, "PYTHONPATH": str(HERE.parents[1])}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=60, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"
