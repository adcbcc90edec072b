"""The autopilot's frame against the vehicle file's, before arming (`check_frame`), with the
parameters as the simulated autopilots report them, and one flight refused end to end."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.frame_check import (
    check_frame,
    frame_parameter_names,
    px4_rotor_parameter_names,
)
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.simvehicle.params import default_parameters
from mavsysid.vehicle.config import load_vehicle, save_vehicle

from tests.support.stream_flights import (
    SimProcess,
    export_excitation,
    flight_dir,
    read_tlog,
    run_stream,
)

SITL_QUAD = load_vehicle("sitl_quad")  # [autopilot] frame = "ardupilot:quad_x"
QUAD_X = load_vehicle("quad_x")  # no [autopilot] frame, rotors in an X


def _plus(config):
    """``config`` turned 45°: its rotors where ArduPilot's "+" quad has them, in its motor
    order (1 right CCW, 2 left CCW, 3 front CW, 4 rear CW)."""
    arm = float(np.hypot(*config.rotor_positions[0, :2]))
    rotors = [replace(config.rotors[0], position=(0.0, -arm, 0.0), direction=1),
              replace(config.rotors[1], position=(0.0, arm, 0.0), direction=1),
              replace(config.rotors[2], position=(arm, 0.0, 0.0), direction=-1),
              replace(config.rotors[3], position=(-arm, 0.0, 0.0), direction=-1)]
    return replace(config, rotors=tuple(rotors), autopilot_frame="ardupilot:quad_plus",
                   name=f"{config.name}_plus")


def _reported(autopilot: Autopilot, config) -> dict[str, float]:
    """The frame parameters the simulated autopilot of ``config`` reports."""
    table = default_parameters(autopilot, config)
    wanted = set(frame_parameter_names(autopilot)) | set(px4_rotor_parameter_names(12))
    return {p.name: p.value for p in table if p.name in wanted}


@pytest.mark.parametrize("config", [SITL_QUAD, QUAD_X, _plus(SITL_QUAD)],
                         ids=["named", "unnamed", "plus"])
@pytest.mark.parametrize("autopilot", [Autopilot.ARDUPILOT, Autopilot.PX4])
def test_the_file_the_autopilot_flies_passes(config, autopilot):
    if config.autopilot_frame and autopilot is Autopilot.PX4:
        config = replace(config, autopilot_frame="px4:" + config.autopilot_frame.split(":")[1])
    report = check_frame(config, autopilot, _reported(autopilot, config))
    assert report.refusals == () and report.warnings == ()


def test_an_x_file_on_a_plus_autopilot_is_refused_naming_both():
    """A "+" autopilot (FRAME_TYPE 0) flown with the X file: the motor outputs would be read
    as rotors 45° from where they are."""
    report = check_frame(SITL_QUAD, Autopilot.ARDUPILOT, {"FRAME_CLASS": 1, "FRAME_TYPE": 0})
    (line,) = report.refusals
    assert "flies ardupilot:quad_plus (FRAME_CLASS 1 (Quad), FRAME_TYPE 0 (Plus))" in line
    assert "sitl_quad says ardupilot:quad_x" in line


def test_an_unnamed_x_file_on_a_plus_autopilot_is_refused():
    """Without [autopilot] frame the rotors must still sit where the autopilot's are."""
    (line,) = check_frame(QUAD_X, Autopilot.ARDUPILOT,
                          {"FRAME_CLASS": 1, "FRAME_TYPE": 0}).refusals
    assert "ardupilot:quad_plus" in line and "not where that frame has them" in line


@pytest.mark.parametrize(("values", "expected"), [
    ({"FRAME_CLASS": 1, "FRAME_TYPE": 12}, "FRAME_TYPE 12 (BetaFlight X), a frame mavsysid "
                                           "has no motor table for"),
    ({"FRAME_CLASS": 2, "FRAME_TYPE": 1}, "flies ardupilot:hexa_x"),
])
def test_other_frames_are_refused(values, expected):
    (line,) = check_frame(SITL_QUAD, Autopilot.ARDUPILOT, values).refusals
    assert expected in line


def test_another_autopilots_numbering_is_refused():
    config = replace(SITL_QUAD, autopilot_frame="px4:quad_x")
    (line,) = check_frame(config, Autopilot.ARDUPILOT, {"FRAME_CLASS": 1,
                                                        "FRAME_TYPE": 1}).refusals
    assert "the vehicle is ardupilot" in line and "px4:quad_x" in line


def test_an_autopilot_that_does_not_say_draws_a_warning():
    report = check_frame(SITL_QUAD, Autopilot.ARDUPILOT, {})
    assert report.refusals == () and "FRAME_CLASS and FRAME_TYPE" in report.warnings[0]


def test_px4_geometry_with_two_motors_swapped_is_refused_naming_the_motor():
    """PX4 ≥ 1.14: the control allocation's rotor 0 and 2 swapped (front right ↔ front left)
    against the file's px4:quad_x."""
    config = replace(SITL_QUAD, autopilot_frame="px4:quad_x")
    values = _reported(Autopilot.PX4, config)
    for key in ("PX", "PY", "KM"):
        values[f"CA_ROTOR0_{key}"], values[f"CA_ROTOR2_{key}"] = (
            values[f"CA_ROTOR2_{key}"], values[f"CA_ROTOR0_{key}"])
    (line,) = check_frame(config, Autopilot.PX4, values).refusals
    assert line.startswith("motor 1 of the autopilot (CA_ROTOR0) is at the front left (-45°)")


def test_px4_without_control_allocation_uses_the_airframe():
    config = replace(SITL_QUAD, autopilot_frame="px4:quad_x")
    assert check_frame(config, Autopilot.PX4, {"SYS_AUTOSTART": 4001}).refusals == ()
    (line,) = check_frame(config, Autopilot.PX4, {"SYS_AUTOSTART": 5001}).refusals
    assert "px4:quad_plus (SYS_AUTOSTART 5001)" in line


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_plus_vehicle_flown_with_the_x_file_is_refused_before_arming(tmp_path: Path):
    """`mavsysid sim` as a "+" quad (its file names ardupilot:quad_plus), `stream --vehicle
    sitl_quad`: exit 3 in one line naming both frames; nothing armed."""
    plus = tmp_path / "sitl_quad_plus.toml"
    save_vehicle(_plus(SITL_QUAD), plus)
    trajectory = export_excitation(tmp_path / "figure.json", 10.0, vehicle="sitl_quad")
    port = free_udp_port()
    logs = tmp_path / "logs"
    with SimProcess(tmp_path / "sim", "--connect", f"udpout:127.0.0.1:{port}", "--vehicle",
                    str(plus), "--speedup", "8"):
        done = run_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--vehicle",
                          "sitl_quad", "--speedup", "8", "--log-dir", str(logs), cwd=tmp_path)
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert done.returncode == 3, done.stderr[-2000:]
    assert len(errors) == 1 and "flight refused: the autopilot flies ardupilot:quad_plus" in (
        errors[0]) and "says ardupilot:quad_x" in errors[0]
    sent = [m for _, m in read_tlog(flight_dir(logs) / "flight.tlog")
            if m.get_srcSystem() == 255 and m.get_type() == "COMMAND_LONG"]
    assert not [m for m in sent if m.command == 400], "an arm was sent"
