"""The console script never shows a bare traceback: internal errors, interrupts, warnings."""

from __future__ import annotations

import argparse
import warnings

import pytest
from mavsysid.vehicle.config_checks import InertiaWarning

import mavsysid.cli.diagnose
from mavsysid.cli.main import DEBUG_ENV, EXIT_INTERNAL, EXIT_INTERRUPTED, main


def _replace_command(monkeypatch: pytest.MonkeyPatch, error: BaseException | None,
                     warning: Warning | None = None) -> None:
    def run(args: argparse.Namespace) -> int:
        if warning is not None:
            warnings.warn(warning, stacklevel=1)
        if error is not None:
            raise error
        return 0

    monkeypatch.setattr(mavsysid.cli.diagnose, "main", run)


def test_unexpected_exception_is_one_line_exit_1(monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    _replace_command(monkeypatch, ZeroDivisionError("division\nby zero"))
    assert main(["diagnose", "flight.ulg"]) == EXIT_INTERNAL == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.splitlines() == [
        "mavsysid diagnose: internal error: ZeroDivisionError: division by zero "
        f"(please report; {DEBUG_ENV}=1 shows the traceback)"]


def test_debug_environment_shows_the_traceback(monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv(DEBUG_ENV, "1")
    _replace_command(monkeypatch, KeyError("x"))
    assert main(["diagnose", "flight.ulg"]) == EXIT_INTERNAL
    err = capsys.readouterr().err
    assert "Traceback" in err
    assert err.splitlines()[-1].startswith("mavsysid diagnose: internal error: KeyError")


def test_systemerror_not_from_an_interrupt_is_internal(monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    _replace_command(monkeypatch, SystemError("bad kernel"))
    assert main(["diagnose", "flight.ulg"]) == EXIT_INTERNAL
    assert "internal error: SystemError: bad kernel" in capsys.readouterr().err


def test_keyboard_interrupt_exits_130(monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    _replace_command(monkeypatch, KeyboardInterrupt())
    assert main(["diagnose", "flight.ulg"]) == EXIT_INTERRUPTED == 130
    assert capsys.readouterr().err == "mavsysid diagnose: interrupted\n"


def test_mavsysid_warning_prints_one_line(monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    _replace_command(monkeypatch, None, InertiaWarning("v.toml: [parameters].J:\n breaks it"))
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["diagnose", "flight.ulg"]) == 0
    expected = "mavsysid diagnose: warning: v.toml: [parameters].J: breaks it\n"
    assert capsys.readouterr().err == expected
