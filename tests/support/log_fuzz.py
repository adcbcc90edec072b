"""Fuzzed flight logs: a clean short flight, value and byte mutations, and every log format.

A `CleanFlight` (a few seconds of the offline simulator, Firefly) is mutated in its values
(`VALUE_MUTATIONS`: ±1e30, NaN/inf, negative or absurd rotor speeds, stretched, reversed,
duplicated or jumping clocks, stuck positions and rotors, wrong units, truncation) and
written as each format the estimator reads (`WRITERS`: ``pose.csv``, MAVLink ``.tlog``,
PX4 ``.ulg``, ArduPilot ``.bin``), integer fields wrapping or saturating as a careless
logger's would; the file may then be mutated in its bytes (`BYTE_MUTATIONS`: truncation,
flipped bytes, junk, a huge or empty file, non-numbers in CSV fields). `fuzz_case` makes
one seeded case. Used by ``tests/estimation/test_fuzzed_logs.py`` and ``bench/fuzz_logs.py``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mavsysid.formats.dataflash import write_dataflash
from mavsysid.formats.ulog import write_ulog
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.frames import enu_to_ned, quaternion_enu_to_ned

from tests.support.hidden import hidden_flight

__all__ = ["BYTE_MUTATIONS", "FORMATS", "VALUE_MUTATIONS", "WRITERS", "CleanFlight",
           "FuzzCase", "clean_flight", "fuzz_case"]

_RAD_S_TO_RPM = 60.0 / (2.0 * np.pi)
_BOOT = 30.0  # s, autopilot time at the flight's t = 0
_EPOCH = 1.7e9  # s, the tlog's receipt clock at boot


@dataclass(frozen=True)
class CleanFlight:
    """A flight as logged: times s, position m (ENU), quaternion (FLU → ENU), rotors rad/s."""

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray


def clean_flight(vehicle: VehicleConfig, directory: Path, seed: int,
                 duration: float = 8.0) -> CleanFlight:
    """A short simulated flight of ``vehicle`` (true θ = its nominal θ), 100 Hz."""
    data = hidden_flight(vehicle, directory, seed=seed, duration=duration)
    return CleanFlight(data.t, data.position, data.quaternion, data.rotor_speeds)


# ------------------------------------------------------------------------- value mutations

Mutation = Callable[[CleanFlight, np.random.Generator], CleanFlight]


def _stretch(f: CleanFlight, rng: np.random.Generator) -> tuple[int, int]:
    """A random stretch of samples [i, j), 0.3 to 3 s long."""
    n = f.t.size
    length = int(rng.integers(30, min(300, n // 2)))
    i = int(rng.integers(0, n - length))
    return i, i + length


def _cells(f: CleanFlight, rng: np.random.Generator, value: float) -> CleanFlight:
    """``value`` (± at random) into 1..20 random cells of one signal."""
    which = str(rng.choice(["t", "position", "quaternion", "rotor_speeds"]))
    a = np.array(getattr(f, which), dtype=float)
    flat = a.reshape(a.shape[0], -1)
    count = int(rng.integers(1, 21))
    rows = rng.integers(0, flat.shape[0], count)
    cols = rng.integers(0, flat.shape[1], count)
    flat[rows, cols] = value * rng.choice([-1.0, 1.0], count)
    return replace(f, **{which: flat.reshape(a.shape)})


def _rotors(f: CleanFlight, rng: np.random.Generator, op: Callable[[np.ndarray], np.ndarray],
            whole: bool = False) -> CleanFlight:
    """``op`` applied to one rotor (or all) over a stretch (or the whole log)."""
    n = f.rotor_speeds.copy()
    i, j = (0, n.shape[0]) if whole or rng.random() < 0.3 else _stretch(f, rng)
    col = slice(None) if rng.random() < 0.3 else int(rng.integers(0, n.shape[1]))
    n[i:j, col] = op(n[i:j, col])
    return replace(f, rotor_speeds=n)


def _hold(f: CleanFlight, rng: np.random.Generator, which: str) -> CleanFlight:
    """A signal stuck at one value over a stretch (or, one time in four, the whole log)."""
    a = np.array(getattr(f, which), dtype=float)
    i, j = (0, a.shape[0]) if rng.random() < 0.25 else _stretch(f, rng)
    a[i:j] = a[i]
    return replace(f, **{which: a})


def _clock(f: CleanFlight, rng: np.random.Generator, kind: str) -> CleanFlight:
    t = f.t.copy()
    if kind == "stretch":
        t = t[0] + (t - t[0]) * float(rng.choice([0.25, 0.5, 0.7, 1.5, 2.0, 4.0]))
    elif kind == "reverse":
        i, j = (0, t.size) if rng.random() < 0.3 else _stretch(f, rng)
        t[i:j] = t[i:j][::-1]
    elif kind == "duplicate":
        rows = rng.integers(1, t.size, int(rng.integers(1, t.size // 2)))
        t[rows] = t[rows - 1]
    elif kind == "jump":
        i = int(rng.integers(1, t.size - 1))
        t[i:] += float(rng.choice([-5.0, -0.05, 0.05, 0.5, 100.0, 1e6]))
    elif kind == "constant":
        t[:] = t[0]
    elif kind == "jitter":
        t = t + rng.normal(0.0, float(rng.choice([0.002, 0.01, 0.05])), t.size)
    return replace(f, t=t)


def _truncate(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    m = int(rng.integers(0, f.t.size // 2))
    return CleanFlight(f.t[:m], f.position[:m], f.quaternion[:m], f.rotor_speeds[:m])


def _quaternion(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    q = f.quaternion.copy()
    i, j = _stretch(f, rng)
    kind = int(rng.integers(0, 3))
    q[i:j] = 0.0 if kind == 0 else (q[i:j] * 2.0 if kind == 1 else q[i:j, ::-1])
    return replace(f, quaternion=q)


#: Value mutations by name: (flight, rng) → mutated flight.
VALUE_MUTATIONS: dict[str, Mutation] = {
    "none": lambda f, rng: f,
    "big_1e30": lambda f, rng: _cells(f, rng, 1e30),
    "nan": lambda f, rng: _cells(f, rng, np.nan),
    "inf": lambda f, rng: _cells(f, rng, np.inf),
    "rotor_negative": lambda f, rng: _rotors(f, rng, np.negative),
    "rotor_absurd": lambda f, rng: _rotors(f, rng, lambda n: n * float(
        rng.choice([3.0, 10.0, 1e3, 1e6]))),
    "rotor_spike": lambda f, rng: _rotors(f, rng, lambda n: n + float(
        rng.choice([-5e3, 5e3, 1e5]))),
    "rotor_zero": lambda f, rng: _rotors(f, rng, np.zeros_like),
    "rotor_stuck": lambda f, rng: _hold(f, rng, "rotor_speeds"),
    "rotor_rpm": lambda f, rng: _rotors(f, rng, lambda n: n * _RAD_S_TO_RPM, whole=True),
    "clock_stretch": lambda f, rng: _clock(f, rng, "stretch"),
    "clock_reverse": lambda f, rng: _clock(f, rng, "reverse"),
    "clock_duplicate": lambda f, rng: _clock(f, rng, "duplicate"),
    "clock_jump": lambda f, rng: _clock(f, rng, "jump"),
    "clock_constant": lambda f, rng: _clock(f, rng, "constant"),
    "clock_jitter": lambda f, rng: _clock(f, rng, "jitter"),
    "position_stuck": lambda f, rng: _hold(f, rng, "position"),
    "attitude_stuck": lambda f, rng: _hold(f, rng, "quaternion"),
    "position_scale": lambda f, rng: replace(f, position=f.position * float(
        rng.choice([1e-3, 1e3]))),
    "position_noise": lambda f, rng: replace(f, position=f.position + rng.normal(
        0.0, float(rng.choice([0.05, 1.0, 100.0])), f.position.shape)),
    "quaternion_bad": _quaternion,
    "truncate": _truncate,
}


# ---------------------------------------------------------------------------------- writers


def _f32(a: np.ndarray) -> np.ndarray:
    """Float values as a float32 field stores them (overflow → ±inf)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(a, dtype=float).astype(np.float32).astype(float)


def _int(a: np.ndarray, bits: int, signed: bool) -> list[int]:
    """Values as a careless logger casts them to an integer field: NaN → 0, wrap-around."""
    a = np.nan_to_num(np.asarray(a, dtype=float), nan=0.0, posinf=2.0**62, neginf=-2.0**62)
    mask, top = (1 << bits) - 1, 1 << (bits - 1)
    wrapped = [v & mask for v in np.clip(np.round(a), -2.0**62, 2.0**62).astype(np.int64)
               .tolist()]
    return [v - (1 << bits) if signed and v >= top else v for v in wrapped]


def write_pose_csv(path: Path, f: CleanFlight) -> None:
    """``pose.csv`` as the writer's header has it, values as Python prints them."""
    k = f.rotor_speeds.shape[1]
    header = ",".join(["t", "x", "y", "z", "qw", "qx", "qy", "qz",
                       *(f"n{i}" for i in range(1, k + 1))])
    rows = np.column_stack([f.t, f.position, f.quaternion, f.rotor_speeds])
    lines = [header, *(",".join(f"{v:.10g}" for v in row) for row in rows)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_tlog(path: Path, f: CleanFlight) -> None:
    """ATT_POS_MOCAP from a ground station and ESC_TELEMETRY rpm from the autopilot."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    p, q = _f32(enu_to_ned(f.position)), _f32(quaternion_enu_to_ned(f.quaternion))
    receipt = _int((_EPOCH + _BOOT + f.t) * 1e6, 64, signed=False)
    usec = _int((_BOOT + f.t) * 1e6, 64, signed=False)
    rpm = np.array([_int(col, 16, signed=False) for col in (f.rotor_speeds * _RAD_S_TO_RPM).T]).T
    k = rpm.shape[1]
    with path.open("wb") as out:
        mav = m.MAVLink(out, srcSystem=1, srcComponent=1)

        def send(stamp: int, msg: object, source: tuple[int, int]) -> None:
            mav.srcSystem, mav.srcComponent = source
            out.write(struct.pack(">Q", stamp))
            mav.send(msg)

        send(receipt[0] if receipt else 0, m.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3), (1, 1))
        for i in range(f.t.size):
            send(receipt[i], m.MAVLink_att_pos_mocap_message(usec[i], list(q[i]), *p[i],
                                                             [0.0] * 21), (255, 190))
            row = [*rpm[i].tolist(), *[0] * (8 - k)]
            for cls, part in ((m.MAVLink_esc_telemetry_1_to_4_message, row[:4]),
                              (m.MAVLink_esc_telemetry_5_to_8_message, row[4:8])):
                send(receipt[i], cls([0] * 4, [0] * 4, [0] * 4, [0] * 4, part, [0] * 4), (1, 1))


_DF_FORMATS = {
    "VISP": (130, "QQIffffffffBB", "TimeUS,RTimeUS,CTimeMS,PX,PY,PZ,Roll,Pitch,Yaw,PErr,AErr,"
                                   "Rst,Ign"),
    "ESC": (133, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
}


def _euler_deg(q: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angles, deg, of NED/FRD quaternions (N, 4) (garbage in, garbage out)."""
    w, x, y, z = q.T
    with np.errstate(all="ignore"):
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.degrees(np.column_stack([roll, pitch, yaw]))


def write_dataflash_log(path: Path, f: CleanFlight) -> None:
    """VISP (motion capture) and ESC rpm per instance, as ArduPilot 4.5 logs them."""
    p = _f32(enu_to_ned(f.position))
    euler = _f32(_euler_deg(quaternion_enu_to_ned(f.quaternion)))
    us = _int((_BOOT + f.t) * 1e6, 64, signed=False)
    ms = _int((_BOOT + f.t) * 1e3, 32, signed=False)
    rpm = _f32(f.rotor_speeds * _RAD_S_TO_RPM)
    rows = []
    for i in range(f.t.size):
        rows.append(("VISP", (us[i], 0, ms[i], *p[i], *euler[i], 0.01, 0.01, 0, 0)))
        for j, v in enumerate(rpm[i]):
            rows.append(("ESC", (us[i], j, v, 0.0, 0.0, 0.0, 0, 0.0, 0, 0.0)))
    write_dataflash(path, _DF_FORMATS, rows)


_ULOG_FORMATS = {
    "vehicle_mocap_odometry": "uint64_t timestamp;uint64_t timestamp_sample;float[3] position;"
                              "float[4] q;uint8_t pose_frame;",
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;float esc_voltage;",
    "esc_status": "uint64_t timestamp;uint8_t esc_count;esc_report[8] esc;",
}


def write_ulog_log(path: Path, f: CleanFlight) -> None:
    """vehicle_mocap_odometry and esc_status rpm (int32), as PX4 logs them."""
    p, q = _f32(enu_to_ned(f.position)), _f32(quaternion_enu_to_ned(f.quaternion))
    us = _int((_BOOT + f.t) * 1e6, 64, signed=False)
    rpm = np.array([_int(c, 32, signed=True) for c in (f.rotor_speeds * _RAD_S_TO_RPM).T]).T
    k = f.rotor_speeds.shape[1]
    odometry = [{"timestamp": us[i], "timestamp_sample": us[i], "pose_frame": 1,
                 **{f"position[{a}]": float(p[i, a]) for a in range(3)},
                 **{f"q[{a}]": float(q[i, a]) for a in range(4)}} for i in range(f.t.size)]
    esc = [{"timestamp": us[i], "esc_count": k,
            **{f"esc[{j}].esc_rpm": int(rpm[i, j]) for j in range(k)}} for i in range(f.t.size)]
    write_ulog(path, _ULOG_FORMATS, {"vehicle_mocap_odometry": odometry, "esc_status": esc})


#: Writers by format (file suffix): (path, flight) → None.
WRITERS: dict[str, Callable[[Path, CleanFlight], None]] = {
    ".csv": write_pose_csv, ".tlog": write_tlog, ".ulg": write_ulog_log,
    ".bin": write_dataflash_log,
}
#: The formats, in a fixed order.
FORMATS: tuple[str, ...] = tuple(WRITERS)


# -------------------------------------------------------------------------- byte mutations


def _flip(data: bytes, rng: np.random.Generator) -> bytes:
    b = bytearray(data)
    for i in rng.integers(0, len(b), int(rng.integers(1, 60))):
        b[i] = int(rng.integers(0, 256))
    return bytes(b)


def _junk_block(data: bytes, rng: np.random.Generator) -> bytes:
    i = int(rng.integers(0, len(data)))
    return data[:i] + rng.bytes(int(rng.integers(1, 4096))) + data[i:]


def _zero_block(data: bytes, rng: np.random.Generator) -> bytes:
    i = int(rng.integers(0, len(data)))
    j = min(len(data), i + int(rng.integers(1, 8192)))
    return data[:i] + bytes(j - i) + data[j:]


def _duplicate_block(data: bytes, rng: np.random.Generator) -> bytes:
    i = int(rng.integers(0, len(data)))
    j = min(len(data), i + int(rng.integers(1, 20000)))
    return data[:j] + data[i:j] + data[j:]


def _csv_words(data: bytes, rng: np.random.Generator) -> bytes:
    """A few numeric fields replaced by words a spreadsheet or logger might leave."""
    lines = data.split(b"\n")
    words = [b"abc", b"true", b"0x1F", b"1e999", b"--", b"", b'"1.0"', b"1,5", b"nan", b"NULL"]
    for _ in range(int(rng.integers(1, 6))):
        i = int(rng.integers(1, max(2, len(lines) - 1)))
        fields = lines[i].split(b",")
        fields[int(rng.integers(0, len(fields)))] = words[int(rng.integers(0, len(words)))]
        lines[i] = b",".join(fields)
    return b"\n".join(lines)


#: Byte mutations by name: (file bytes, rng) → new bytes. ``huge`` is handled by
#: `fuzz_case` (it writes a sparse file, not bytes).
BYTE_MUTATIONS: dict[str, Callable[[bytes, np.random.Generator], bytes]] = {
    "none": lambda data, rng: data,
    "cut": lambda data, rng: data[:int(rng.integers(0, max(1, len(data))))],
    "flip": _flip,
    "junk": _junk_block,
    "zeros": _zero_block,
    "duplicate": _duplicate_block,
    "empty": lambda data, rng: b"",
    "junk_tail": lambda data, rng: data + rng.bytes(int(rng.integers(1, 3_000_000))),
    "words": _csv_words,
    "huge": lambda data, rng: data,
}


@dataclass(frozen=True)
class FuzzCase:
    """One fuzzed log: its file, format, mutations and seed."""

    path: Path
    suffix: str
    value_mutation: str
    byte_mutation: str
    seed: int


def fuzz_case(directory: Path, clean: CleanFlight, suffix: str, value_mutation: str,
              byte_mutation: str, seed: int, huge_bytes: int = 0) -> FuzzCase:
    """Write one fuzzed log into ``directory`` (created).

    Parameters
    ----------
    directory : Path
        Where the log goes (as ``flight<suffix>``, ``pose.csv`` for CSV).
    clean : CleanFlight
        The flight before mutation.
    suffix : str
        A key of `WRITERS`.
    value_mutation, byte_mutation : str
        Keys of `VALUE_MUTATIONS`, `BYTE_MUTATIONS`.
    seed : int
        Of the mutations' random choices.
    huge_bytes : int
        For ``huge``: the sparse file's size, bytes.
    """
    rng = np.random.default_rng(seed)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / ("pose.csv" if suffix == ".csv" else f"flight{suffix}")
    WRITERS[suffix](path, VALUE_MUTATIONS[value_mutation](clean, rng))
    if byte_mutation == "huge":
        with path.open("r+b") as out:  # sparse: the size without the disk space
            out.truncate(huge_bytes)
    elif byte_mutation != "none":
        path.write_bytes(BYTE_MUTATIONS[byte_mutation](path.read_bytes(), rng))
    return FuzzCase(path, suffix, value_mutation, byte_mutation, seed)
