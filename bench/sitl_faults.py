"""Faults in flight on real ArduCopter SITL: does every flight end safe and put back?

One fresh SITL per case (``../shared/sitl/arducopter --model x`` with ``copter.parm`` and
``vehicle/configs/sitl_quad.parm``, loopback TCP only), one ``mavsysid stream`` of a gentle
20 s excitation of ``sitl_quad`` in the box -2,-2,0.5,2,2,2.5 (``--set-limits``: stock
ArduCopter limits, raised for the flight and restored), and one fault:

* ``none``: no fault (the reference);
* ``wind``: SIM_WIND_SPD 8 m/s with SIM_WIND_T 1 (full speed at every height) from boot;
* ``weak_motor``: SIM_ENGINE_MUL 0.7, SIM_ENGINE_FAIL 1 (motor 1 at 70 %), set 3 s into
  the trajectory;
* ``gps_loss``: SIM_GPS1_ENABLE 0, 3 s into the trajectory (ArduCopter's EKF failsafe
  lands; the streamer hands over, then ``mavsysid restore --land`` as it says);
* ``battery``: SIM_BATT_CAP_AH 0.3 from boot, so the voltage falls as it flies; in this
  build it does not (BAT.Volt stays 12.6 V at up to 39 A: the multicopter's battery model
  takes its capacity from the frame model, not from SIM_BATT_CAP_AH), so SIM_BATT_VOLTAGE
  is also stepped down from 3 s into the trajectory, 0.3 V every 2 s to 10.2 V, through
  BATT_LOW_VOLT (10.5 V);
* ``link_cut``: the streamer talks to SITL through a TCP relay that drops everything for
  3 s, 3 s into the trajectory (then ``mavsysid restore --land``);
* ``killed``: the streamer killed (SIGKILL) 3 s into the trajectory, then ``mavsysid
  restore --land``.

A second ground station on SITL's SERIAL1 (system 254) records position, arming and
landed state throughout and sets the fault parameters. Each case records:

* **fence**: the farthest the vehicle went outside the box (the fence is 1.5 m outside), by
  SITL's true position (SIMSTATE) and by the autopilot's estimate (LOCAL_POSITION_NED,
  which drifts once the GPS is lost);
* **landed and disarmed**: the last heartbeat disarmed, the last height at the take-off
  height;
* **parameters**: the full parameter list read before the flight (SERIAL0, before the
  streamer connects) against the one read at the end (SERIAL1): differences other than the
  fault's own SIM_* parameters and what ArduCopter changes itself (STAT_* counters,
  MIS_TOTAL when it stores home as mission item 0 at its first GPS fix) must be none;
* **log intact**: ``flight.tlog`` parses with no bad data, ``pose.csv`` reads, ``meta.json``
  is final (``running`` false) or says it was killed; SITL's own DataFlash log parses;
* **estimation**: ``mavsysid estimate`` and ``mavsysid diagnose`` on ``flight.tlog`` and on
  SITL's ``.BIN``: exit code and their last line, kept for judging (this bench does not
  judge them).

    nice python bench/sitl_faults.py --work DIR [--cases none wind …] [--keep]
    python bench/sitl_faults.py --report DIR     # the table of what DIR holds

Each case takes 2–4 min (boot about 25 s, pre-arm checks, the flight, landing, the
estimates) at SITL's real-time pace.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from mavsysid.flight.ground.geofence import FENCE_MARGIN  # noqa: E402
from mavsysid.flight.loopback_ports import free_tcp_port  # noqa: E402
from mavsysid.flight.mavlink_setup import load_mavutil  # noqa: E402

from tests.support.sitl import running_sitl  # noqa: E402

SITL_PARMS = REPO / "vehicle" / "configs" / "sitl_quad.parm"
BOX = (-2.0, -2.0, 0.5, 2.0, 2.0, 2.5)
#: Boot-time parameters of each case (written to a .parm loaded after sitl_quad.parm).
BOOT = {"wind": {"SIM_WIND_SPD": 8.0, "SIM_WIND_T": 1.0, "SIM_WIND_DIR": 90.0},
        "battery": {"SIM_BATT_CAP_AH": 0.3}}
#: Parameters set 3 s into the trajectory.
IN_FLIGHT = {"weak_motor": {"SIM_ENGINE_MUL": 0.7, "SIM_ENGINE_FAIL": 1.0},
             "gps_loss": {"SIM_GPS1_ENABLE": 0.0}}
CASES = ("none", "wind", "weak_motor", "gps_loss", "battery", "link_cut", "killed")
#: Parameters ArduCopter sets by itself (not mavsysid's to put back), by pattern: its flight
#: statistics (STAT_*); home stored as mission item 0 at the first GPS fix (MIS_TOTAL);
#: sensor ids found and gyros calibrated at boot (INS_*_ID, INS_GYR*OFFS_*, INS_GYR*_CALTEMP);
#: the barometers' ground pressure, taken again at arming (BARO*_GND_PRESS); the magnetic
#: declination looked up from the GPS position (COMPASS_DEC); the hover throttle it learns
#: in flight (MOT_THST_HOVER, MOT_HOVER_LEARN 2).
AUTOPILOT_OWN = re.compile(r"^(STAT_|MIS_TOTAL$|INS_(ACC|GYR)\d?_ID$|INS_GYR\d?OFFS_|"
                           r"INS_GYR\d?_CALTEMP$|BARO\d_GND_PRESS$|COMPASS_DEC$|"
                           r"MOT_THST_HOVER$)")
#: Parameters a case's fault hides (SITL lists a disabled GPS's settings no more).
FAULT_HIDES = {"gps_loss": "SIM_GPS1_"}
#: SITL's true position, SIMSTATE (ardupilotmega), asked for at 5 Hz.
_SIMSTATE = 164
_EARTH_RADIUS = 6378137.0
FAULT_AT = 3.0  # s into the trajectory


def mavsysid(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess[str]:
    """``python -m mavsysid ARGS`` to completion."""
    return subprocess.run([sys.executable, "-m", "mavsysid", *args], capture_output=True,
                          text=True, timeout=timeout, check=False, cwd=REPO)


# --- the link: parameters, an observer, a relay ---------------------------------------------

def read_all_parameters(conn: Any, timeout: float = 60.0) -> dict[str, float]:
    """Every parameter of the vehicle on ``conn`` (PARAM_REQUEST_LIST, gaps asked again)."""
    values: dict[str, float] = {}
    count = None
    deadline = time.monotonic() + timeout
    conn.mav.param_request_list_send(1, 1)
    while time.monotonic() < deadline and (count is None or len(values) < count):
        m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1.0)
        if m is None:
            conn.mav.param_request_list_send(1, 1)
            continue
        values[m.param_id] = float(m.param_value)
        count = m.param_count
    if count is None or len(values) < count:
        raise RuntimeError(f"read {len(values)} of {count} parameters")
    return values


def connect(port: int, system: int, timeout: float = 60.0) -> Any:
    """A pymavlink connection to 127.0.0.1:``port`` that has seen the vehicle's heartbeat."""
    mavutil = load_mavutil()
    deadline = time.monotonic() + timeout
    while True:
        try:
            conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=system,
                                              source_component=190, retries=1)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)
    if conn.wait_heartbeat(timeout=timeout) is None:
        raise RuntimeError(f"no heartbeat on 127.0.0.1:{port}")
    return conn


class Observer(threading.Thread):
    """SITL's SERIAL1 as a second ground station: records the flight, sets parameters."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.conn = connect(port, 254)
        # LOCAL_POSITION_NED, EXTENDED_SYS_STATE, SYS_STATUS, SIMSTATE
        for msg_id in (32, 245, 1, _SIMSTATE):
            self.conn.mav.command_long_send(1, 1, 511, 0, msg_id, 2e5, 0, 0, 0, 0, 0)
        self.positions: list[tuple[float, float, float, float]] = []  # t, east, north, up
        #: SITL's true horizontal position from its first report: t, east, north (m).
        self.truth: list[tuple[float, float, float]] = []
        self._truth_origin: tuple[float, float] | None = None
        self.armed: list[tuple[float, bool]] = []
        self.voltages: list[tuple[float, float]] = []
        self.texts: list[str] = []
        self.landed_state: int | None = None
        self.mode = ""
        self._halt = threading.Event()
        self._params: dict[str, float] = {}

    def run(self) -> None:
        while not self._halt.is_set():
            try:
                m = self.conn.recv_match(blocking=True, timeout=0.2)
            except Exception as error:  # the link closed under us: stop recording
                self.texts.append(f"observer stopped: {type(error).__name__}: {error}")
                return
            if m is not None:
                self._note(m)

    def _note(self, m: Any) -> None:
        kind, now = m.get_type(), time.monotonic()
        if kind == "LOCAL_POSITION_NED":
            self.positions.append((now, m.y, m.x, -m.z))
        elif kind == "SIMSTATE" and (m.lat or m.lng):
            lat, lon = m.lat * 1e-7, m.lng * 1e-7
            if self._truth_origin is None:
                self._truth_origin = (lat, lon)
            lat0, lon0 = self._truth_origin
            self.truth.append((now, math.radians(lon - lon0) * _EARTH_RADIUS
                               * math.cos(math.radians(lat0)),
                               math.radians(lat - lat0) * _EARTH_RADIUS))
        elif kind == "HEARTBEAT" and m.get_srcSystem() == 1 and m.type != 6:
            self.armed.append((now, bool(m.base_mode & 128)))
            self.mode = load_mavutil().mode_string_v10(m)
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state = m.landed_state
        elif kind == "SYS_STATUS":
            self.voltages.append((now, m.voltage_battery * 1e-3))
        elif kind == "STATUSTEXT":
            self.texts.append(m.text)
        elif kind == "PARAM_VALUE":
            self._params[m.param_id] = float(m.param_value)

    def set(self, values: dict[str, float]) -> None:
        """Set parameters (the fault), checked by their echo."""
        for name, value in values.items():
            for _ in range(10):
                self.conn.mav.param_set_send(1, 1, name.encode(), value, 9)
                time.sleep(0.3)
                echo = self._params.get(name)
                if echo is not None and math.isclose(echo, value, rel_tol=1e-6):
                    break

    def all_parameters(self) -> dict[str, float]:
        self._halt.set()
        self.join(timeout=5.0)
        return read_all_parameters(self.conn)

    def close(self) -> None:
        self._halt.set()
        self.conn.close()


class Relay:
    """A TCP relay from a local port to SITL's SERIAL0 that can drop everything for a while."""

    def __init__(self, target: int) -> None:
        self.port, self.target = free_tcp_port(), target
        self._server = socket.create_server(("127.0.0.1", self.port))
        self._cut_until = 0.0
        threading.Thread(target=self._serve, daemon=True).start()

    def cut(self, seconds: float) -> None:
        """Drop every byte, both ways, for ``seconds``."""
        self._cut_until = time.monotonic() + seconds

    def _serve(self) -> None:
        client, _ = self._server.accept()
        upstream = socket.create_connection(("127.0.0.1", self.target))
        for a, b in ((client, upstream), (upstream, client)):
            threading.Thread(target=self._pipe, args=(a, b), daemon=True).start()

    def _pipe(self, source: socket.socket, sink: socket.socket) -> None:
        """Copy until either side closes, then close both (SITL's SERIAL0 is freed)."""
        try:
            while data := source.recv(65536):
                if time.monotonic() >= self._cut_until:
                    sink.sendall(data)
        except OSError:
            pass
        for end in (source, sink):
            with contextlib.suppress(OSError):
                end.close()


# --- one case ----------------------------------------------------------------------------

def trajectory(path: Path) -> Path:
    """The gentle 20 s excitation of sitl_quad in BOX (peak acceleration about 2 m/s²)."""
    from mavsysid.flight.offline.excitation import ExcitationSpec, excitation_trajectory
    from mavsysid.formats.trajectory_file import trajectory_file_for, write_trajectory_file
    from mavsysid.vehicle.config import load_vehicle

    figure = excitation_trajectory(ExcitationSpec(duration=20.0, amplitude=(0.8, 0.6, 0.3)))
    write_trajectory_file(path, trajectory_file_for(figure, load_vehicle("sitl_quad"), box=BOX))
    return path


def start_stream(plan: Path, link: str, logs: Path, err: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "mavsysid", "stream", str(plan), "--connect", link, "--vehicle",
         "sitl_quad", "--set-limits", "--box", ",".join(f"{b:g}" for b in BOX),
         "--prearm-timeout", "300", "--log-dir", str(logs)],
        stdout=subprocess.PIPE, stderr=err.open("w"), text=True, cwd=REPO)


def wait_for(condition: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no {what} within {timeout:g} s")
        time.sleep(0.2)


def fly_case(case: str, sitl: Any, work: Path) -> dict[str, Any]:
    """Fly one case on a running SITL; what happened, for `judge`."""
    before = connect(sitl.port, 253)  # SERIAL0, closed again before the streamer connects
    try:
        boot = read_all_parameters(before)
    finally:
        before.close()
    relay = Relay(sitl.port) if case == "link_cut" else None
    link = f"tcp:127.0.0.1:{relay.port if relay else sitl.port}"
    err = work / "stream.err"
    stream = start_stream(trajectory(work / "gentle.json"), link, work / "logs", err)
    observer = Observer(sitl.port + 2)
    observer.start()
    try:
        wait_for(lambda: "streaming the" in err.read_text() or stream.poll() is not None,
                 420.0, "trajectory start")
        streaming = time.monotonic()
        if stream.poll() is None:
            time.sleep(FAULT_AT)
            inject(case, observer, relay, stream)
        stream.wait(timeout=400)
        time.sleep(3.0)  # the observer's next heartbeats
        restore = None
        if (observer.armed and observer.armed[-1][1]) or stream.returncode != 0:
            restore = mavsysid("restore", str(flight_dir(work / "logs")), "--connect",
                               f"tcp:127.0.0.1:{sitl.port}", "--land", timeout=600)
        time.sleep(2.0)
        end = observer.all_parameters()
    finally:
        if stream.poll() is None:
            stream.kill()
        observer.close()
    return {"case": case, "exit": stream.returncode, "stderr": err.read_text(),
            "streaming_at": streaming, "restore": None if restore is None else {
                "exit": restore.returncode, "stderr": restore.stderr, "stdout": restore.stdout},
            "boot": boot, "end": end, "positions": observer.positions,
            "truth": observer.truth,
            "armed": observer.armed, "voltages": observer.voltages, "texts": observer.texts,
            "mode": observer.mode}


def sag(observer: Observer) -> None:
    """SIM_BATT_VOLTAGE from 12.3 V down to 10.2 V, 0.3 V every 2 s (a thread)."""
    def steps() -> None:
        for volts in np.arange(12.3, 10.15, -0.3):
            observer.set({"SIM_BATT_VOLTAGE": float(round(volts, 2))})
            time.sleep(2.0)

    threading.Thread(target=steps, daemon=True).start()


def inject(case: str, observer: Observer, relay: Relay | None,
           stream: subprocess.Popen[str]) -> None:
    """The case's fault, 3 s into the trajectory."""
    if case in IN_FLIGHT:
        observer.set(IN_FLIGHT[case])
    elif case == "battery":
        sag(observer)
    elif case == "link_cut" and relay is not None:
        relay.cut(3.0)
    elif case == "killed":
        stream.send_signal(signal.SIGKILL)


def flight_dir(logs: Path) -> Path:
    (found,) = [p for p in Path(logs).iterdir() if p.is_dir()]
    return found


# --- judging what happened ---------------------------------------------------------------

def outside_box(east: float, north: float, up: float) -> float:
    """Distance outside BOX, m (its floor is the ground: only the sides and the top count)."""
    d = (max(BOX[0] - east, 0.0, east - BOX[3]), max(BOX[1] - north, 0.0, north - BOX[4]),
         max(0.0, up - BOX[5]))
    return math.sqrt(sum(x * x for x in d))


def parameter_diff(boot: dict[str, float], end: dict[str, float], case: str
                   ) -> dict[str, dict[str, Any]]:
    """Parameters that differ, in three groups: the fault's own, the autopilot's own, and
    the rest (which mavsysid must have put back)."""
    fault = set(BOOT.get(case, {})) | set(IN_FLIGHT.get(case, {}))
    if case == "battery":
        fault.add("SIM_BATT_VOLTAGE")
    hidden = FAULT_HIDES.get(case)
    groups: dict[str, dict[str, Any]] = {"fault": {}, "autopilot": {}, "left_changed": {}}
    for name in sorted(boot.keys() | end.keys()):
        a, b = boot.get(name), end.get(name)
        if a is not None and b is not None and math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9):
            continue
        mine = name in fault or (hidden is not None and name.startswith(hidden) and b is None)
        group = ("fault" if mine else "autopilot"
                 if AUTOPILOT_OWN.match(name) else "left_changed")
        groups[group][name] = [a, b]
    return groups


def logs_intact(directory: Path, scratch: Path) -> dict[str, Any]:
    """Whether the flight's logs and SITL's own log read back."""
    from mavsysid.formats.flight_dir import read_meta
    from mavsysid.formats.poselog import read_pose_log

    out: dict[str, Any] = {}
    tlog = load_mavutil().mavlink_connection(str(directory / "flight.tlog"))
    kinds: dict[str, int] = {}
    while (m := tlog.recv_match()) is not None:
        kinds[m.get_type()] = kinds.get(m.get_type(), 0) + 1
    out["tlog_messages"], out["tlog_bad_data"] = sum(kinds.values()), kinds.get("BAD_DATA", 0)
    out["pose_rows"] = len(read_pose_log(directory / "pose.csv", 4))
    meta = read_meta(directory / "meta.json")
    out["meta"] = {k: meta.get(k) for k in ("status", "reason", "running", "samples")}
    out["motor_watch"] = meta.get("motor_watch")
    bins = sorted((scratch / "logs").glob("*.BIN"))
    out["bin"] = str(bins[-1]) if bins else None
    if bins:
        dataflash = load_mavutil().mavlink_connection(str(bins[-1]))
        count = 0
        while dataflash.recv_msg() is not None:
            count += 1
        out["bin_messages"] = count
    return out


def estimation(directory: Path, binary: str | None) -> dict[str, Any]:
    """estimate and diagnose on the tlog and on SITL's .BIN, recorded as they answer: exit
    code, last line, each parameter's error against sitl_quad's reference θ with its σ and
    status, the effects diagnose names. Nothing here judges the answers."""
    from mavsysid.vehicle.config import PARAMETER_NAMES, load_vehicle

    reference = dict(zip(PARAMETER_NAMES, load_vehicle("sitl_quad").theta, strict=True))
    out: dict[str, Any] = {}
    for name, log in (("tlog", directory / "flight.tlog"), ("bin", binary)):
        if log is None:
            continue
        est = directory / f"estimate_{name}.json"
        done = mavsysid("estimate", str(log), "--vehicle", "sitl_quad", "-o", str(est))
        result: dict[str, Any] = {"exit": done.returncode, "last": _last_line(done),
                                  "stdout": done.stdout}
        if done.returncode == 0:
            params = json.loads(est.read_text())["parameters"]
            result["errors"] = {p: {"error_pct": round(100 * (v["value"] / reference[p] - 1), 2),
                                    "sigma_pct": round(100 * v["sigma"] / reference[p], 2),
                                    "status": v["status"]} for p, v in params.items()}
            diag_file = directory / f"diagnosis_{name}.json"
            diag = mavsysid("diagnose", str(log), "--vehicle", "sitl_quad", "--estimate",
                            str(est), "-o", str(diag_file))
            result["diagnose"] = {"exit": diag.returncode, "last": _last_line(diag)}
            if diag.returncode == 0:
                found = json.loads(diag_file.read_text())
                result["diagnose"]["effects"] = [e["name"] for e in found["effects"]]
        out[name] = result
    return out


def _last_line(done: subprocess.CompletedProcess[str]) -> str:
    lines = [ln for ln in (done.stderr + done.stdout).splitlines() if ln.strip()]
    errors = [ln for ln in lines if ": error:" in ln]
    return (errors or lines or [""])[-1]


def farthest_outside(flown: dict[str, Any]) -> tuple[float, float]:
    """The farthest outside the box, m: by SITL's true horizontal position (with the
    autopilot's height), and by the autopilot's own estimate (which drifts without GPS)."""
    estimate = max((outside_box(e, n, u) for _, e, n, u in flown["positions"]),
                   default=math.nan)
    heights = flown["positions"]
    truth, k = [], 0
    for t, east, north in flown["truth"]:
        while k + 1 < len(heights) and heights[k + 1][0] <= t:
            k += 1
        truth.append(outside_box(east, north, heights[k][3] if heights else 0.0))
    return max(truth, default=math.nan), estimate


def judge(flown: dict[str, Any], work: Path, scratch: Path) -> dict[str, Any]:
    """The case's record: safety figures, the parameter diff, the logs, the estimates."""
    worst, estimated = farthest_outside(flown)
    first = flown["positions"][0] if flown["positions"] else None
    last = flown["positions"][-1] if flown["positions"] else None
    directory = flight_dir(work / "logs")
    diff = parameter_diff(flown["boot"], flown["end"], flown["case"])
    volts = [v for _, v in flown["voltages"]]
    record = {
        "case": flown["case"], "stream_exit": flown["exit"],
        "stream_last": [ln for ln in flown["stderr"].splitlines() if ln.strip()][-6:],
        "restore": flown["restore"], "farthest_outside_box_m": round(worst, 3),
        "farthest_outside_box_estimated_m": round(estimated, 3),
        "inside_fence": bool(worst <= FENCE_MARGIN),
        "disarmed": bool(flown["armed"]) and not flown["armed"][-1][1],
        "final_height_m": None if last is None or first is None else round(last[3] - first[3], 3),
        "final_mode": flown["mode"], "parameters": diff,
        "parameters_back": not diff["left_changed"],
        "battery_v": [round(min(volts), 2), round(max(volts), 2)] if volts else None,
        "autopilot_texts": flown["texts"][-15:], "logs": logs_intact(directory, scratch),
    }
    record["estimation"] = estimation(directory, record["logs"].get("bin"))
    return record


def run_case(case: str, root: Path) -> dict[str, Any]:
    work = root / case
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    defaults = [SITL_PARMS]
    if case in BOOT:
        extra = work / "fault.parm"
        extra.write_text("".join(f"{k} {v:g}\n" for k, v in BOOT[case].items()))
        defaults.append(extra)
    started = time.monotonic()
    with running_sitl(work / "sitl", defaults=defaults, model="x") as sitl:
        flown = fly_case(case, sitl, work)
    record = judge(flown, work, work / "sitl")
    record["wall_s"] = round(time.monotonic() - started, 1)
    (work / "record.json").write_text(json.dumps(record, indent=1, default=str))
    return record


# --- the table -----------------------------------------------------------------------------

def report(root: Path) -> str:
    """The markdown table of every case recorded under ``root``."""
    rows = ["| case | stream | restore | farthest outside box (true / estimated) | disarmed | "
            "parameters back | logs | estimate (tlog) | estimate (.BIN) |", "|" + "---|" * 9]
    for case in CASES:
        path = root / case / "record.json"
        if not path.is_file():
            continue
        r = json.loads(path.read_text())
        logs = r["logs"]
        intact = (logs["tlog_bad_data"] == 0 and logs["pose_rows"] > 0
                  and bool(logs.get("bin_messages")))
        est = r.get("estimation", {})
        back = ("yes" if r["parameters_back"]
                else "NO: " + ", ".join(r["parameters"]["left_changed"]))
        rows.append(
            f"| {case} | exit {r['stream_exit']} | "
            f"{'—' if r['restore'] is None else 'exit ' + str(r['restore']['exit'])} | "
            f"{r['farthest_outside_box_m']:.2f} / "
            f"{r.get('farthest_outside_box_estimated_m', math.nan):.2f} m | "
            f"{'yes' if r['disarmed'] else 'NO'} | "
            f"{back} | "
            f"{'yes' if intact else 'NO'} | {_verdict(est.get('tlog'))} | "
            f"{_verdict(est.get('bin'))} |")
    return "\n".join(rows)


def _verdict(result: dict[str, Any] | None) -> str:
    """What estimate and diagnose answered, in a cell: determined parameters' errors."""
    if result is None:
        return "—"
    if result["exit"] != 0:
        return f"exit {result['exit']}: {result['last'].split('error: ')[-1][:100]}"
    shown = [f"{p} {e['error_pct']:+.1f}±{e['sigma_pct']:.1f} %"
             for p, e in result.get("errors", {}).items() if e["status"] == "determined"]
    diag = result.get("diagnose", {})
    named = (", ".join(diag.get("effects", [])) or "nothing") if diag.get("exit") == 0 else (
        f"exit {diag.get('exit')}")
    return f"{'; '.join(shown) or 'nothing determined'}; diagnose: {named}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, help="folder for the cases' files")
    parser.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES))
    parser.add_argument("--report", type=Path, metavar="DIR",
                        help="print the table of the cases recorded in DIR and stop")
    args = parser.parse_args()
    if args.report is not None:
        print(report(args.report))
        return 0
    if args.work is None:
        parser.error("--work DIR is required")
    for case in args.cases:
        print(f"== {case}", flush=True)
        try:
            record = run_case(case, args.work)
        except Exception as error:  # one case failing to run must not hide the others
            print(f"   could not run: {type(error).__name__}: {error}", flush=True)
            continue
        print(f"   stream exit {record['stream_exit']}, outside box "
              f"{record['farthest_outside_box_m']} m, disarmed {record['disarmed']}, "
              f"parameters back {record['parameters_back']} ({record['wall_s']} s)", flush=True)
    print(report(args.work))
    return 0


if __name__ == "__main__":
    sys.exit(main())
