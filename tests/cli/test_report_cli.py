"""``--report``, ``--history`` and the stage messages of ``estimate`` and ``diagnose``."""

from __future__ import annotations

import html.parser
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mavsysid.estimation.readers import load_flight
from mavsysid.pipeline.simulate import run_offline_flight
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle
from mavsysid.vehicle.model_effects import MotorLag

from mavsysid.cli import main
from tests.support.hidden import hidden_flight
from tests.support.rrd import series, temporal_rows

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class _Images(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.sources: list[str] = []
        self.scripts = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "img":
            self.sources.append(dict(attrs)["src"] or "")
        self.scripts += tag == "script"


def _check_page(index: Path) -> list[str]:
    """The page's image sources; each is a PNG beside it; no script."""
    parsed = _Images()
    parsed.feed(index.read_text(encoding="utf-8"))
    assert parsed.scripts == 0 and parsed.sources
    for name in parsed.sources:
        assert (index.parent / name).read_bytes().startswith(PNG_SIGNATURE)
    return parsed.sources


@pytest.fixture(scope="module")
def pose_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 12 s simulated Firefly flight."""
    logs = tmp_path_factory.mktemp("logs")
    return run_offline_flight("firefly", logs, "f", duration=12.0).directory / "pose.csv"


@pytest.mark.slow
def test_estimate_report_history_and_stages(pose_csv, tmp_path, capsys):
    """-v shows the stages on stderr; stdout is the usual table; the files are written."""
    assert main(["estimate", str(pose_csv)]) == 0
    plain = capsys.readouterr()
    assert plain.err == ""  # not a terminal and not -v: no stage messages
    report, history = tmp_path / "rep", tmp_path / "h.csv"
    out = tmp_path / "e.json"
    assert main(["-v", "estimate", str(pose_csv), "--report", str(report),
                 "--history", str(history), "-o", str(out)]) == 0
    verbose = capsys.readouterr()
    assert verbose.out == plain.out + f"wrote estimate {out}, history {history}, report {report}\n"
    stages = [line.split("] ", 1)[1] for line in verbose.err.splitlines()]
    # A stage's progress lines ("batch refinement 2/30: …") repeat its first word.
    first_words = [s.split(" ")[0] for s in stages]
    collapsed = [w for i, w in enumerate(first_words) if i == 0 or w != first_words[i - 1]]
    assert collapsed == ["reading", "fitting", "the", "filtering", "fitting", "batch", "writing"]
    assert all(line.startswith("mavsysid estimate: [") for line in verbose.err.splitlines())
    assert sorted(_check_page(report / "index.html")) == sorted(
        ["parameters.png", "innovations.png", "rotor_speeds.png", "wrench.png"])
    doc = json.loads(out.read_text())
    table = pd.read_csv(history)
    pd.testing.assert_frame_equal(table, pd.read_csv(report / "history.csv"))
    assert len(table) == len(load_flight(pose_csv, load_vehicle("firefly")).t)
    for name in PARAMETER_NAMES:
        assert table[name].iloc[-1] == doc["filter"][name]["value"]
        assert table[f"{name}_sigma"].iloc[-1] == pytest.approx(doc["filter"][name]["sigma"],
                                                                rel=1e-12)


def test_quiet_estimate_prints_no_stages(pose_csv, capsys):
    """-q: nothing on stdout or stderr, even with -v's habit of stage messages."""
    assert main(["-q", "estimate", str(pose_csv), "--no-refine"]) == 0
    captured = capsys.readouterr()
    assert (captured.out, captured.err) == ("", "")


@pytest.mark.slow
def test_diagnose_report_and_rotor_speeds_in_the_recording(tmp_path, capsys):
    """diagnose --report writes the residual figures and page; --rrd has the rotor speeds."""
    directory = tmp_path / "lag"
    config = load_vehicle("firefly")
    hidden_flight(config, directory, [MotorLag(tau=0.04)], seed=3, duration=20.0)
    log = directory / "pose.csv"
    report, rrd = tmp_path / "rep", tmp_path / "d.rrd"
    assert main(["diagnose", str(log), "--report", str(report), "--rrd", str(rrd)]) == 0
    assert capsys.readouterr().out.endswith(f"wrote recording {rrd}, report {report}\n")
    assert sorted(_check_page(report / "index.html")) == sorted(
        ["residuals.png", "rotor_speeds.png", "wrench.png"])
    assert "motor_lag" in (report / "index.html").read_text(encoding="utf-8")
    flight = load_flight(log, config)
    rows = temporal_rows(rrd)
    for i in range(config.rotor_count):
        assert rows[f"/rotors/n{i + 1}"] == len(flight.t)
    t, n1 = series(rrd, "/rotors/n1")
    np.testing.assert_allclose(t, flight.t, atol=1e-9)
    np.testing.assert_array_equal(n1, flight.rotor_speeds[:, 0])
