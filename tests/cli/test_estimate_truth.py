"""``estimate --truth``: each parameter against a simulator's true θ, error and z-score."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.pipeline.simulate import read_truth
from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

from mavsysid.cli import main
from mavsysid.errors import InputError
from tests.support.stream_flights import SimProcess, export_excitation, flight_dir, run_stream

ROW = re.compile(r"^  (\w+)\s+(\S+)\s+(\S+)\s+(\S+)\s+([+-]\S+)\s+([+-]\S+)$")


def _rows(out: str) -> dict[str, tuple[float, ...]]:
    block = out.split("Against the truth", 1)[1]
    return {m.group(1): tuple(float(g) for g in m.groups()[1:])
            for line in block.splitlines() if (m := ROW.match(line))}


def test_truth_is_read_from_a_meta_json_or_its_directory(tmp_path):
    """A simulator's meta.json (or its directory) gives θ in the parameters' order; other
    files are one-line input errors."""
    values = dict(zip(PARAMETER_NAMES, (1.0, 2.0, 3.0, 4.0, 5.0, 6.0), strict=True))
    (tmp_path / "meta.json").write_text(json.dumps({"truth": {"parameters": values}}))
    assert read_truth(tmp_path).tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert read_truth(tmp_path / "meta.json").tolist() == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    (tmp_path / "meta.json").write_text(json.dumps({"source": "mavlink-stream"}))
    with pytest.raises(InputError, match=r"no truth\.parameters"):
        read_truth(tmp_path)
    with pytest.raises(InputError, match="no such file"):
        read_truth(tmp_path / "nowhere")


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_sim_stream_estimate_truth(tmp_path, capsys):
    """`mavsysid sim --truth-log` → `stream` → `estimate --truth DIR`: a row per parameter
    whose error and z agree with the estimate's own JSON and the sim's true θ."""
    trajectory = export_excitation(tmp_path / "figure.json", 12.0)
    port = free_udp_port()
    truth_dir = tmp_path / "truth"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--speedup",
                    "8", "--theta-scale", "1.1,1,0.9,1.2,0.8,1", "--truth-log",
                    str(truth_dir)) as sim:
        sim.wait_ready(timeout=300)  # a busy machine starts it slowly
        result = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup",
                            "8", "--log-dir", str(tmp_path / "logs"), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    pose = flight_dir(tmp_path / "logs") / "pose.csv"
    out_json = tmp_path / "estimate.json"
    assert main(["estimate", str(pose), "--truth", str(truth_dir), "-o", str(out_json)]) == 0
    rows = _rows(capsys.readouterr().out)
    truth = read_truth(truth_dir)
    estimate = json.loads(out_json.read_text())
    assert list(rows) == list(PARAMETER_NAMES)
    for j, name in enumerate(PARAMETER_NAMES):
        value, sigma, true, error, z = rows[name]
        assert true == pytest.approx(truth[j], rel=2e-3)
        v, s = (estimate["parameters"][name][k] for k in ("value", "sigma"))
        assert value == pytest.approx(v, rel=2e-3) and sigma == pytest.approx(s, rel=5e-3)
        assert error == pytest.approx(100 * (v - truth[j]) / truth[j], abs=0.01)
        assert z == pytest.approx((v - truth[j]) / s, abs=0.01)
    # The sim's hidden θ, not the vehicle file's prior, is what the rows compare with.
    prior = load_vehicle("firefly").theta
    assert truth == pytest.approx(prior * np.array([1.1, 1.0, 0.9, 1.2, 0.8, 1.0]))
