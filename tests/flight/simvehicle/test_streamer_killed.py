"""kill -9 of `mavsysid stream` mid-flight: the simulated vehicle ends inside box + margin.

The vehicle (in this process, lock-stepped with the streamer, so that the flight before
the kill is the same on an idle or a busy machine) carries the fence and timeout that
`mavsysid.flight.ground.geofence` gives it before arming: the box plus `FENCE_MARGIN` as
an inclusion polygon and a maximum altitude, ArduPilot FENCE_ACTION Brake or Land and
GUID_TIMEOUT, PX4 GF_ACTION Land, COM_OF_LOSS_T and COM_OBL_RC_ACT Land. They are set on
the vehicle here, with the values the streamer's own `fence_plan`/`fence_parameters`
compute, so that the test holds the simulated autopilots to their behaviour whether or
not the streamer has installed the fence itself by then (it then sets the same again).
The streamer is killed while the vehicle flies fast and outwards; its true path (the
sim's truth log) must stay inside box + margin, and it must end there.
"""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import numpy as np
import pytest
from mavsysid.flight.autopilot_modes import ARDUCOPTER_MODES, Autopilot
from mavsysid.flight.ground.geofence import (
    FENCE_MARGIN,
    VehicleOrigin,
    fence_parameters,
    fence_plan,
)
from mavsysid.flight.loopback_ports import free_udp_port
from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
from mavsysid.flight.simvehicle.endpoint import SimEndpoint, SimSettings
from mavsysid.flight.simvehicle.fence import FenceItem
from mavsysid.flight.simvehicle.link import mavlink as M
from mavsysid.flight.simvehicle.physics import ORIGIN
from mavsysid.vehicle.config import load_vehicle

from tests.support.stream_flights import BOX, export_excitation, start_stream, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore::UserWarning")]

SPEEDUP = 4.0
DURATION = 12.0
#: Sim seconds the vehicle is watched after the kill (PX4 lands within them).
AFTER_KILL = 20.0


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory) -> Path:
    """A 12 s excitation figure inside the test box."""
    return export_excitation(tmp_path_factory.mktemp("traj") / "figure12.json", DURATION)


def peak_speed() -> float:
    """The figure's highest horizontal speed, m/s."""
    flat = excitation_trajectory(ExcitationSpec(duration=DURATION)).flat_outputs(
        np.linspace(0.0, DURATION, 4001))
    return float(np.max(np.hypot(flat.velocity[:, 0], flat.velocity[:, 1])))


def set_fence(endpoint: SimEndpoint, autopilot: Autopilot, **overrides: float
              ) -> dict[str, float]:
    """Give the vehicle the streamer's fence of `BOX` (see the module docstring), with
    ``overrides`` of its parameters."""
    plan = fence_plan(BOX, FENCE_MARGIN, VehicleOrigin(ORIGIN[0], ORIGIN[1], "test"),
                      endpoint.settings.start)
    count = float(len(plan.polygon))
    items = [FenceItem(M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_FRAME_GLOBAL,
                       (count, 0.0, 0.0, 0.0), lat, lon) for lat, lon in plan.polygon]
    required, optional = fence_parameters(autopilot, plan, polygon_ok=True)
    values = {**optional, **required, **overrides}
    assert endpoint.autopilot.fence.upload(items) == M.MAV_MISSION_ACCEPTED
    for name, value in values.items():
        assert endpoint.params.set(name, value), name
    return values


def outside_box(positions: np.ndarray) -> np.ndarray:
    """Per-axis distance (m, ≥ 0) of each ENU position (n, 3) outside `BOX`'s sides and top.

    Below the box's floor counts as inside: the fence has no floor, and landing is what the
    failsafes do.
    """
    low, high = np.array([BOX[0], BOX[1], -np.inf]), np.asarray(BOX[3:])
    return np.maximum(np.maximum(low - positions, positions - high), 0.0)


def fast_and_outwards(endpoint: SimEndpoint, speed: float) -> bool:
    """The vehicle flies (armed, in the air) at ≥ ``speed`` away from the box centre."""
    v, ap = endpoint.vehicle, endpoint.autopilot
    if not ap.armed or v.landed or ap.spec.kind != "guided":
        return False
    velocity = v.velocity()[:2]
    centre = 0.5 * (np.asarray(BOX[:2]) + np.asarray(BOX[3:5]))
    return bool(np.hypot(*velocity) >= speed and velocity @ (v.position[:2] - centre) > 0.0)


def heading_out(endpoint: SimEndpoint, horizon: float, distance: float) -> bool:
    """The guided target, extrapolated over ``horizon`` s as the autopilot does until its
    timeout, ends ≥ ``distance`` m outside the box (the worst moment to lose the link)."""
    ap, target = endpoint.autopilot, endpoint.vehicle.target.copy()
    if not ap.armed or endpoint.vehicle.landed or ap.spec.kind != "guided":
        return False
    ahead = target[0:3] + target[3:6] * horizon + 0.5 * target[6:9] * horizon**2
    return bool(outside_box(ahead[None, :]).max() >= distance)


def killed_flight(tmp_path: Path, trajectory: Path, autopilot: Autopilot,
                  kill_when=None, preset: dict[str, float] | None = None) -> dict:
    """Fly, kill -9 the streamer when ``kill_when(endpoint)`` (default: fast and outwards),
    watch; the figures of the flight.

    ``preset``: give the vehicle the streamer's fence with these parameter overrides here,
    and stream with ``--no-fence`` (else the streamer installs its fence itself).
    """
    if kill_when is None:
        kill_when = lambda e: fast_and_outwards(e, 0.8 * peak_speed())  # noqa: E731
    port = free_udp_port()
    truth = tmp_path / "truth"
    settings = SimSettings(autopilot=autopilot, speedup=SPEEDUP, lockstep=True, truth_log=truth,
                           sensor_noise=False)
    endpoint = SimEndpoint(f"udpout:127.0.0.1:{port}", load_vehicle("firefly"), settings)
    extra = [] if preset is None else ["--no-fence"]
    if preset is not None:
        set_fence(endpoint, autopilot, **preset)
    thread = threading.Thread(target=endpoint.run, name="sim", daemon=True)
    thread.start()
    try:
        stream = start_stream(trajectory, "--connect", f"udp:127.0.0.1:{port}", "--speedup",
                              str(SPEEDUP), "--lockstep", "--log-dir", str(tmp_path / "logs"),
                              *extra, cwd=tmp_path)
        try:
            wait_for(lambda: kill_when(endpoint) or stream.poll() is not None, 180,
                     "the moment to kill the streamer")
            assert stream.poll() is None, (tmp_path / "stream.err").read_text()
            stream.send_signal(signal.SIGKILL)
            kill_time = endpoint.vehicle.time_us * 1e-6
            values = {p.name: p.value for p in endpoint.params
                      if p.name.startswith(("FENCE_", "GF_", "GUID_", "COM_OF", "COM_OBL"))}
            zones = endpoint.autopilot.fence.regions.count
            kill_speed = float(np.hypot(*endpoint.vehicle.velocity()[:2]))
        finally:
            if stream.poll() is None:
                stream.kill()
            stream.wait(timeout=10)
        end = kill_time + AFTER_KILL
        wait_for(lambda: endpoint.vehicle.time_us * 1e-6 >= end, 4.0 * AFTER_KILL / SPEEDUP + 30,
                 f"{AFTER_KILL:g} s of sim time after the kill")
        events = list(endpoint.autopilot.events)
        mode, armed = endpoint.autopilot.mode, endpoint.autopilot.armed
    finally:
        endpoint.stop()
        thread.join(10.0)
    rows = np.genfromtxt(truth / "truth.csv", delimiter=",", names=True)
    after = rows[rows["t"] >= kill_time]
    positions = np.column_stack([after["x"], after["y"], after["z"]])
    out = outside_box(positions)
    speeds = np.linalg.norm(np.diff(positions, axis=0), axis=1) / np.diff(after["t"])
    return {"values": values, "zones": zones, "kill_time": kill_time, "kill_speed": kill_speed,
            "max_outside_axis": float(out.max()),
            "max_outside": float(np.linalg.norm(out, axis=1).max()),
            "final": positions[-1], "outside": out.max(axis=1), "speeds": speeds,
            "mode": mode, "armed": armed, "events": events,
}


@pytest.mark.parametrize("autopilot", [Autopilot.ARDUPILOT, Autopilot.PX4],
                         ids=["ardupilot", "px4"])
def test_killed_streamer_leaves_the_vehicle_inside_box_and_margin(tmp_path, trajectory,
                                                                  autopilot):
    """kill -9 while fast: the true path stays within box + FENCE_MARGIN, and ends there.

    The fence and the timeouts are the streamer's own (uploaded over the mission protocol,
    parameters set with PARAM_SET)."""
    flight = killed_flight(tmp_path, trajectory, autopilot)
    values = flight["values"]
    assert flight["zones"] == 1  # the streamer's polygon
    if autopilot is Autopilot.ARDUPILOT:
        assert values["FENCE_ENABLE"] == 1 and values["GUID_TIMEOUT"] < 3.0
    else:
        assert values["GF_ACTION"] != 0 and values["COM_OBL_RC_ACT"] == 4
    print(f"{autopilot.name}: killed at {flight['kill_time']:.2f} s sim, "
          f"{flight['kill_speed']:.2f} m/s; max outside the box {flight['max_outside']:.3f} m "
          f"(largest axis {flight['max_outside_axis']:.3f} m); final {flight['final']}; "
          f"values {values}")
    assert flight["kill_speed"] >= 0.8 * peak_speed()
    assert flight["max_outside_axis"] <= FENCE_MARGIN
    assert np.all(outside_box(flight["final"][None, :]) <= FENCE_MARGIN)
    if autopilot is Autopilot.PX4:  # COM_OBL_RC_ACT Land: down and disarmed
        assert flight["final"][2] < 0.05 and not flight["armed"]


def test_fence_brakes_a_vehicle_whose_guided_timeout_was_left_at_3_s(tmp_path, trajectory):
    """ArduCopter with the stock GUID_TIMEOUT (3 s; a vehicle whose timeout could not be
    lowered), killed when the extrapolated target heads out: the polygon fence's Brake stops
    it within its braking distance of the fence (BRAKE_MODE_DECEL_RATE 7.5 m/s², taken at
    half for the 25 Hz check, the mode's ramp and the controller's lag), where it holds."""
    flight = killed_flight(tmp_path, trajectory, Autopilot.ARDUPILOT,
                           kill_when=lambda e: heading_out(e, 3.0, 3.0),
                           preset={"GUID_TIMEOUT": 3.0})
    outside, speeds = flight["outside"], flight["speeds"]
    crossing = int(np.argmax(outside > FENCE_MARGIN))
    assert outside[crossing] > FENCE_MARGIN, "the vehicle never reached the fence"
    v = float(speeds[max(crossing - 1, 0)])
    beyond = flight["max_outside_axis"] - FENCE_MARGIN
    print(f"stock GUID_TIMEOUT: killed at {flight['kill_time']:.2f} s sim; crossed the fence "
          f"at {v:.2f} m/s; max outside the box {flight['max_outside']:.3f} m (axis "
          f"{flight['max_outside_axis']:.3f} m, {beyond:.3f} m beyond the fence); final "
          f"{flight['final']}")
    assert flight["mode"] == ARDUCOPTER_MODES["BRAKE"] and flight["armed"]
    assert beyond <= v**2 / (2.0 * 0.5 * 7.5) + 0.04 * v
    assert np.all(speeds[-100:] < 0.05)  # stopped, holding
