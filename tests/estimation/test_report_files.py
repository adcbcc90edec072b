"""Tests of the report folder, the history CSV and the stage messages of ``estimate``."""

from __future__ import annotations

import html.parser
import io

import numpy as np
import pandas as pd
import pytest
from mavsysid.estimation.balance.fit import compare_wrench
from mavsysid.estimation.flight import FlightData
from mavsysid.estimation.progress import StageLog, progress_wanted, report_stage, stage_listener
from mavsysid.estimation.report.figures import (
    ESTIMATE_REPORT_FILES,
    ReportTable,
    html_page,
    write_estimate_report,
)
from mavsysid.estimation.report.text import HISTORY_COLUMNS, history_frame, write_history_csv
from mavsysid.vehicle.config import PARAMETER_NAMES
from mavsysid.vehicle.rotation import quat_exp

from tests.estimation.test_report import synthetic_result

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class _Collector(html.parser.HTMLParser):
    """Tags, image sources and table cells of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.images: list[str] = []
        self.cells: list[str] = []
        self._in_cell = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        self._in_cell = tag in ("td", "th")
        if tag == "img":
            self.images.append(dict(attrs)["src"] or "")

    def handle_data(self, data: str) -> None:
        if self._in_cell:
            self.cells.append(data)
            self._in_cell = False


def _flight(result, rotors: int = 6, seed: int = 5) -> FlightData:
    """A pose and rotor speeds over the result's time span (seeded, smooth)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(result.history.t[0], result.history.t[-1], 800)
    position = np.column_stack([np.sin(0.7 * t), np.cos(0.4 * t), 1.0 + 0.05 * t])
    quaternion = quat_exp(np.column_stack([0.1 * np.sin(t), 0.1 * np.cos(1.3 * t), 0.2 * t]))
    speeds = 550.0 + 40.0 * np.sin(t[:, None] + rng.uniform(0, 6, rotors))
    return FlightData(t, position, quaternion, speeds, "logs/synthetic/pose.csv")


# --- history CSV -----------------------------------------------------------------------


def test_history_csv_holds_the_filters_theta_and_sigma(tmp_path):
    """Columns t, each θ_j and its σ, NIS; one row per filter step; values exact."""
    result = synthetic_result(n=157)
    h = result.history
    path = tmp_path / "out" / "history.csv"
    write_history_csv(path, h)
    table = pd.read_csv(path)
    assert tuple(table.columns) == HISTORY_COLUMNS
    assert HISTORY_COLUMNS[:3] == ("t", "c_T", "c_T_sigma")
    assert len(table) == 157
    np.testing.assert_array_equal(table["t"], h.t)
    for j, name in enumerate(PARAMETER_NAMES):
        np.testing.assert_array_equal(table[name], h.theta[:, j])
        np.testing.assert_array_equal(table[f"{name}_sigma"], h.theta_sigma[:, j])
    np.testing.assert_array_equal(table["nis"], h.nis)
    assert sorted(p.name for p in path.parent.iterdir()) == ["history.csv"]


def test_history_frame_matches_the_csv(tmp_path):
    """The frame written is the frame computed."""
    result = synthetic_result(seed=3, n=40)
    write_history_csv(tmp_path / "h.csv", result.history)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "h.csv"),
                                  history_frame(result.history))


# --- the report folder -----------------------------------------------------------------


@pytest.mark.parametrize("truth", [True, False])
def test_report_folder_has_pngs_csv_and_a_page_that_shows_them(tmp_path, firefly, truth):
    """Every listed PNG is a real PNG; the page references each; no script, no network."""
    result = synthetic_result(truth=truth)
    index = write_estimate_report(tmp_path / "rep", result, _flight(result), firefly,
                                  "logs/a/pose.csv")
    assert index == tmp_path / "rep" / "index.html"
    names = [name for name, _ in ESTIMATE_REPORT_FILES]
    assert sorted(p.name for p in index.parent.iterdir()) == sorted(
        [*names, "history.csv", "index.html"])
    for name in names:
        data = (index.parent / name).read_bytes()
        assert data.startswith(PNG_SIGNATURE) and len(data) > 10_000
    page = index.read_text(encoding="utf-8")
    parsed = _Collector()
    parsed.feed(page)
    assert parsed.images == names
    assert "script" not in parsed.tags and "http" not in page
    for name in PARAMETER_NAMES:
        assert name in parsed.cells
    assert ("true" in parsed.cells) is truth
    assert len(pd.read_csv(index.parent / "history.csv")) == len(result.history.t)


def test_html_page_escapes_what_it_is_given():
    """Text from logs and notes cannot inject markup."""
    page = html_page("a <b>", ["x & y"], [ReportTable("c", ("h<",), (("<td>",),))],
                     [("f\".png", "cap <i>")], ["<script>"])
    assert "<b>" not in page and "<script>" not in page and "<td>&lt;td&gt;</td>" in page
    assert 'src="f&quot;.png"' in page


# --- model vs measured wrench ----------------------------------------------------------


def test_measured_wrench_equals_the_model_on_a_consistent_flight(firefly):
    """A hover at the rotor speeds that hold it: measured and model force agree (m g)."""
    t = np.linspace(0.0, 4.0, 401)
    hover = np.sqrt(firefly.mass * 9.81 / (firefly.rotor_count * firefly.theta[0]))
    # A slow climb at constant speed: every pose fresh, no acceleration.
    flight = FlightData(t, np.column_stack([np.zeros_like(t), np.zeros_like(t), 1.0 + 1e-3 * t]),
                        np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1)),
                        np.full((t.size, firefly.rotor_count), hover), "hover")
    c = compare_wrench(flight, firefly, firefly.theta)
    assert 300 < c.t.size < 401
    np.testing.assert_allclose(c.measured_force, c.model_force, atol=1e-9)
    np.testing.assert_allclose(c.measured_force[:, 2], firefly.mass * 9.81, rtol=1e-9)
    np.testing.assert_allclose(c.measured_torque, c.model_torque, atol=1e-9)


def test_measured_wrench_sees_a_wrong_thrust_coefficient(firefly):
    """With c_T 10 % too high the model's thrust is 10 % above what the hover demands."""
    t = np.linspace(0.0, 4.0, 401)
    hover = np.sqrt(firefly.mass * 9.81 / (firefly.rotor_count * firefly.theta[0]))
    # A slow climb at constant speed: every pose fresh, no acceleration.
    flight = FlightData(t, np.column_stack([np.zeros_like(t), np.zeros_like(t), 1.0 + 1e-3 * t]),
                        np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1)),
                        np.full((t.size, firefly.rotor_count), hover), "hover")
    theta = firefly.theta * np.array([1.1, 1, 1, 1, 1, 1])
    c = compare_wrench(flight, firefly, theta)
    np.testing.assert_allclose(c.model_force[:, 2] / c.measured_force[:, 2], 1.1, rtol=1e-9)


# --- stage messages --------------------------------------------------------------------


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize(("verbosity", "tty", "shown"), [
    (-1, True, False), (0, True, True), (0, False, False), (1, False, True), (2, True, True),
])
def test_progress_is_shown_on_a_terminal_or_with_verbose_never_quiet(verbosity, tty, shown):
    stream = _Tty() if tty else io.StringIO()
    assert progress_wanted(verbosity, stream) is shown


def test_stages_reach_the_listener_only_inside_its_block():
    """report_stage goes to the installed listener, and nowhere outside the block."""
    seen: list[str] = []
    report_stage("before")
    with stage_listener(seen.append):
        report_stage("filtering")
        with stage_listener(None):
            report_stage("hidden")
        report_stage("refinement")
    report_stage("after")
    assert seen == ["filtering", "refinement"]


def test_stage_log_writes_one_line_per_stage_with_elapsed_time():
    stream = io.StringIO()
    ticks = iter([10.0, 10.0, 12.25])
    log = StageLog("mavsysid estimate", stream, clock=lambda: next(ticks))
    log("reading a.csv")
    log("filtering 10 samples")
    assert stream.getvalue().splitlines() == [
        "mavsysid estimate: [   0.0 s] reading a.csv",
        "mavsysid estimate: [   2.2 s] filtering 10 samples",
    ]
