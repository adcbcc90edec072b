"""Fuzzed flight logs: a clean short flight, value and byte mutations, and every log format.

A `CleanFlight` (a few seconds of the offline simulator, Firefly, with its simulated IMU:
gyro and accelerometer with noise and biases, at the pose's rate) is mutated in its values
(`VALUE_MUTATIONS`: ±1e30, NaN/inf, negative or absurd rotor speeds, stretched, reversed,
duplicated or jumping clocks, stuck positions and rotors, wrong units, truncation; and of
the IMU alone, ``imu_*``: bad cells, a drop-out, a stuck sensor, deg/s, g, flipped or
swapped axes, FRD read as FLU, an offset or non-monotonic clock, another rate, duplicated
rows, partial coverage, no IMU) and written as each format the estimator reads
(`WRITERS`: ``pose.csv`` with its IMU columns, MAVLink ``.tlog`` with ArduPilot RAW_IMU or
PX4 HIGHRES_IMU, PX4 ``.ulg`` with sensor_combined, ArduPilot ``.bin`` with IMU), integer
fields wrapping or saturating as a careless logger's would; the file may then be mutated
in its bytes (`BYTE_MUTATIONS`: truncation, flipped bytes, junk, a huge or empty file,
non-numbers in CSV fields). `fuzz_case` makes one seeded case. Used by
``tests/estimation/test_fuzzed_logs.py`` and ``bench/fuzz_logs.py``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mavsysid.formats.dataflash import ARDUPILOT_MESSAGES, write_dataflash
from mavsysid.formats.poselog import IMU_COLUMNS, read_pose_log
from mavsysid.formats.tlog import STANDARD_GRAVITY
from mavsysid.formats.ulog import PX4_TOPICS, write_ulog
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.frames import enu_to_ned, flu_to_frd, quaternion_enu_to_ned

from tests.support.hidden import hidden_flight

__all__ = ["BYTE_MUTATIONS", "FORMATS", "IMU_MESSAGE_CHOICES", "IMU_MUTATIONS", "VALUE_MUTATIONS",
           "WRITERS", "CleanFlight", "FuzzCase", "clean_flight", "fuzz_case", "write_tlog"]

_RAD_S_TO_RPM = 60.0 / (2.0 * np.pi)
_BOOT = 30.0  # s, autopilot time at the flight's t = 0
_EPOCH = 1.7e9  # s, the tlog's receipt clock at boot


@dataclass(frozen=True)
class CleanFlight:
    """A flight as logged: times s, position m (ENU), quaternion (FLU → ENU), rotors rad/s;
    the IMU on its own clock: times s, gyro rad/s and specific force m/s², body FLU (None:
    no IMU), and its offset from the centre of gravity, m, body FLU."""

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    rotor_speeds: np.ndarray
    imu_t: np.ndarray | None = None
    gyro: np.ndarray | None = None
    accel: np.ndarray | None = None
    imu_position: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def has_imu(self) -> bool:
        """Whether the flight carries an IMU."""
        return self.imu_t is not None and self.gyro is not None and self.accel is not None


def clean_flight(vehicle: VehicleConfig, directory: Path, seed: int,
                 duration: float = 8.0) -> CleanFlight:
    """A short simulated flight of ``vehicle`` (true θ = its nominal θ), 100 Hz, with the
    simulator's IMU (noise and biases) on the pose's rows."""
    data = hidden_flight(vehicle, directory, seed=seed, duration=duration)
    log = read_pose_log(directory / "pose.csv", vehicle.rotor_count)
    assert log.gyro is not None and log.accel is not None, "the simulator records the IMU"
    position = (0.0, 0.0, 0.0) if vehicle.imu_position is None else tuple(vehicle.imu_position)
    return CleanFlight(data.t, data.position, data.quaternion, data.rotor_speeds,
                       np.array(log.t), np.array(log.gyro), np.array(log.accel),
                       position)  # type: ignore[arg-type]


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
    return _with_clock(f, replace(f, **{which: flat.reshape(a.shape)}))


def _with_clock(before: CleanFlight, after: CleanFlight) -> CleanFlight:
    """``after`` with the IMU's clock changed as the pose's, where the IMU shares it (it
    is logged on the pose's rows, or stamped by the same clock)."""
    if not before.has_imu or not np.array_equal(before.imu_t, before.t, equal_nan=True):
        return after
    return replace(after, imu_t=after.t.copy())


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
    return _with_clock(f, replace(f, t=t))


def _truncate(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    m = int(rng.integers(0, f.t.size // 2))
    imu = {} if not f.has_imu else {"imu_t": f.imu_t[:m], "gyro": f.gyro[:m],  # type: ignore
                                    "accel": f.accel[:m]}  # type: ignore[index]
    return replace(f, t=f.t[:m], position=f.position[:m], quaternion=f.quaternion[:m],
                   rotor_speeds=f.rotor_speeds[:m], **imu)


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


# ----------------------------------------------------------------------- IMU value mutations

_IMU_SENSORS = ("gyro", "accel")


def _sensors(rng: np.random.Generator) -> tuple[str, ...]:
    """The gyro, the accelerometer or both, at random."""
    return (_IMU_SENSORS, ("gyro",), ("accel",))[int(rng.integers(0, 3))]


def _imu_rows(f: CleanFlight, keep: np.ndarray) -> CleanFlight:
    """The IMU samples ``keep`` (a boolean mask or an index array) only."""
    return replace(f, imu_t=f.imu_t[keep], gyro=f.gyro[keep],  # type: ignore[index]
                   accel=f.accel[keep])  # type: ignore[index]


def _imu_cells(f: CleanFlight, rng: np.random.Generator, value: float) -> CleanFlight:
    """``value`` (± at random) into 1..20 random cells of the IMU's time, gyro or accel."""
    which = str(rng.choice(["imu_t", "gyro", "accel"]))
    a = np.array(getattr(f, which), dtype=float)
    flat = a.reshape(a.shape[0], -1)
    count = int(rng.integers(1, 21))
    flat[rng.integers(0, flat.shape[0], count), rng.integers(0, flat.shape[1], count)] = (
        value * rng.choice([-1.0, 1.0], count))
    return replace(f, **{which: flat.reshape(a.shape)})


def _imu_stretch(f: CleanFlight, rng: np.random.Generator) -> tuple[int, int]:
    """A random stretch of IMU samples [i, j), 0.3 to 3 s at 100 Hz."""
    n = f.imu_t.size  # type: ignore[union-attr]
    length = int(rng.integers(30, max(31, min(300, n // 2))))
    i = int(rng.integers(0, max(1, n - length)))
    return i, i + length


def _imu_dropout(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    """No IMU samples over a stretch (the logger's buffer overran)."""
    i, j = _imu_stretch(f, rng)
    keep = np.ones(f.imu_t.size, dtype=bool)  # type: ignore[union-attr]
    keep[i:j] = False
    return _imu_rows(f, keep)


def _imu_stuck(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    """A sensor reading one value over a stretch (or, one time in four, the whole log)."""
    out = {}
    for name in _sensors(rng):
        a = np.array(getattr(f, name), dtype=float)
        i, j = (0, a.shape[0]) if rng.random() < 0.25 else _imu_stretch(f, rng)
        a[i:j] = a[i]
        out[name] = a
    return replace(f, **out)


def _imu_scaled(f: CleanFlight, name: str, factor: float) -> CleanFlight:
    return replace(f, **{name: getattr(f, name) * factor})


def _imu_axes(f: CleanFlight, rng: np.random.Generator, kind: str) -> CleanFlight:
    """One axis negated, two swapped, or FRD written as FLU, of one sensor or both."""
    out = {}
    for name in _sensors(rng) if kind != "frd" else _IMU_SENSORS:
        a = np.array(getattr(f, name), dtype=float)
        if kind == "flip":
            a[:, int(rng.integers(0, 3))] *= -1.0
        elif kind == "swap":
            i, j = rng.choice(3, 2, replace=False)
            a[:, [i, j]] = a[:, [j, i]]
        else:
            a = flu_to_frd(a)
        out[name] = a
    return replace(f, **out)


def _imu_clock(f: CleanFlight, rng: np.random.Generator, kind: str) -> CleanFlight:
    """The IMU's clock off the pose's: an offset, a reversed stretch, jitter, a jump."""
    t = np.array(f.imu_t, dtype=float)
    if kind == "offset":
        t = t + float(rng.choice([-2.0, -0.3, -0.05, -0.02, 0.01, 0.03, 0.1, 0.5, 5.0]))
    elif kind == "reverse":
        i, j = _imu_stretch(f, rng)
        t[i:j] = t[i:j][::-1]
    elif kind == "jitter":
        t = t + rng.normal(0.0, float(rng.choice([0.001, 0.005, 0.02])), t.size)
    elif kind == "jump":
        t[int(rng.integers(1, t.size - 1)):] += float(rng.choice([-3.0, -0.05, 0.05, 1.0]))
    return replace(f, imu_t=t)


def _imu_rate(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    """The IMU at another rate than the pose's (resampled from the flight's 100 Hz)."""
    rate = float(rng.choice([10.0, 25.0, 50.0, 200.0, 400.0, 1000.0]))
    t0, t1 = float(f.imu_t[0]), float(f.imu_t[-1])  # type: ignore[index]
    t = t0 + np.arange(int((t1 - t0) * rate) + 1) / rate
    resample = [np.column_stack([np.interp(t, f.imu_t, a[:, k])  # type: ignore[arg-type]
                                 for k in range(3)]) for a in (f.gyro, f.accel)]
    return replace(f, imu_t=t, gyro=resample[0], accel=resample[1])


def _imu_duplicate(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    """A few IMU rows logged twice (same time and values)."""
    n = f.imu_t.size  # type: ignore[union-attr]
    rows = np.sort(np.concatenate([np.arange(n), rng.integers(0, n, int(rng.integers(1, 20)))]))
    return _imu_rows(f, rows)


def _imu_partial(f: CleanFlight, rng: np.random.Generator) -> CleanFlight:
    """The IMU over only the first or the last 10 to 70 % of the flight."""
    n = f.imu_t.size  # type: ignore[union-attr]
    m = int(n * float(rng.uniform(0.1, 0.7)))
    keep = slice(0, m) if rng.random() < 0.5 else slice(n - m, n)
    return _imu_rows(f, np.arange(n)[keep])


#: IMU value mutations by name (the pose and rotors untouched).
IMU_MUTATIONS: dict[str, Mutation] = {
    "imu_big_1e30": lambda f, rng: _imu_cells(f, rng, 1e30),
    "imu_nan": lambda f, rng: _imu_cells(f, rng, np.nan),
    "imu_inf": lambda f, rng: _imu_cells(f, rng, np.inf),
    "imu_dropout": _imu_dropout,
    "imu_stuck": _imu_stuck,
    "imu_deg_s": lambda f, rng: _imu_scaled(f, "gyro", 180.0 / np.pi),
    "imu_g": lambda f, rng: _imu_scaled(f, "accel", 1.0 / STANDARD_GRAVITY),
    "imu_axis_flip": lambda f, rng: _imu_axes(f, rng, "flip"),
    "imu_axis_swap": lambda f, rng: _imu_axes(f, rng, "swap"),
    "imu_frd": lambda f, rng: _imu_axes(f, rng, "frd"),
    "imu_time_offset": lambda f, rng: _imu_clock(f, rng, "offset"),
    "imu_time_reverse": lambda f, rng: _imu_clock(f, rng, "reverse"),
    "imu_time_jitter": lambda f, rng: _imu_clock(f, rng, "jitter"),
    "imu_time_jump": lambda f, rng: _imu_clock(f, rng, "jump"),
    "imu_rate": _imu_rate,
    "imu_duplicate": _imu_duplicate,
    "imu_partial": _imu_partial,
    "imu_absent": lambda f, rng: replace(f, imu_t=None, gyro=None, accel=None),
}
VALUE_MUTATIONS.update(IMU_MUTATIONS)


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


def _imu_on_rows(t: np.ndarray, f: CleanFlight) -> tuple[np.ndarray, np.ndarray]:
    """The IMU on the pose's rows as the streamer writes it: row i's own sample where the
    IMU shares the pose's clock; else the latest sample at or before each row's time,
    however old, and rows before the first sample left out. The rows kept (bool, (N,))
    and their IMU, shape (M, 6)."""
    values = np.column_stack([f.gyro, f.accel])
    if np.array_equal(f.imu_t, t, equal_nan=True):
        return np.ones(t.size, dtype=bool), values
    finite = np.isfinite(f.imu_t)  # type: ignore[arg-type]
    order = np.argsort(f.imu_t[finite], kind="stable")  # type: ignore[index]
    times, values = f.imu_t[finite][order], values[finite][order]  # type: ignore[index]
    j = np.searchsorted(times, t, side="right") - 1
    keep = j >= 0
    return keep, values[j[keep]]


def write_pose_csv(path: Path, f: CleanFlight) -> None:
    """``pose.csv`` as the writer's header has it, values as Python prints them; the IMU's
    columns on the pose's rows (`_imu_on_rows`)."""
    k = f.rotor_speeds.shape[1]
    names = ["t", "x", "y", "z", "qw", "qx", "qy", "qz", *(f"n{i}" for i in range(1, k + 1))]
    columns = [f.t, f.position, f.quaternion, f.rotor_speeds]
    if f.has_imu:
        names += IMU_COLUMNS
        keep, imu = _imu_on_rows(f.t, f)
        columns = [c[keep] for c in columns] + [imu]
    rows = np.column_stack(columns)
    lines = [",".join(names), *(",".join(f"{v:.10g}" for v in row) for row in rows)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _imu_chunks(f: CleanFlight) -> list[np.ndarray]:
    """The IMU samples written after each pose row: in file order, spread evenly over the
    rows (whatever their stamps say, as a logger's buffer interleaves them)."""
    n = f.t.size
    if not f.has_imu or n == 0:
        return [np.empty(0, dtype=int)] * n
    m = f.imu_t.size  # type: ignore[union-attr]
    bounds = np.ceil(np.arange(n + 1) * m / n).astype(int)
    return [np.arange(bounds[i], bounds[i + 1]) for i in range(n)]


def _imu_frd(f: CleanFlight) -> tuple[np.ndarray, np.ndarray]:
    """Gyro and accelerometer in body FRD, as autopilots log them."""
    return flu_to_frd(f.gyro), flu_to_frd(f.accel)  # type: ignore[arg-type]


def write_tlog(path: Path, f: CleanFlight, imu_message: str = "RAW_IMU") -> None:
    """ATT_POS_MOCAP from a ground station; ESC_TELEMETRY rpm, SYSTEM_TIME and the IMU
    (``imu_message``: ArduPilot's RAW_IMU in mG and mrad/s with INS_POS1_*, or PX4's
    HIGHRES_IMU in SI floats with EKF2_IMU_POS_*) from the autopilot."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    p, q = _f32(enu_to_ned(f.position)), _f32(quaternion_enu_to_ned(f.quaternion))
    receipt = _int((_EPOCH + _BOOT + f.t) * 1e6, 64, signed=False)
    usec = _int((_BOOT + f.t) * 1e6, 64, signed=False)
    boot_ms = _int((_BOOT + f.t) * 1e3, 32, signed=False)
    rpm = np.array([_int(col, 16, signed=False) for col in (f.rotor_speeds * _RAD_S_TO_RPM).T]).T
    k = rpm.shape[1]
    imu = _tlog_imu(f, imu_message, m) if f.has_imu else []
    with path.open("wb") as out:
        mav = m.MAVLink(out, srcSystem=1, srcComponent=1)

        def send(stamp: int, msg: object, source: tuple[int, int]) -> None:
            mav.srcSystem, mav.srcComponent = source
            out.write(struct.pack(">Q", stamp))
            mav.send(msg)

        first = receipt[0] if receipt else 0
        send(first, m.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3), (1, 1))
        if f.has_imu:
            prefix = "INS_POS1_" if imu_message == "RAW_IMU" else "EKF2_IMU_POS_"
            for a, value in zip("XYZ", flu_to_frd(np.array(f.imu_position)), strict=True):
                send(first, m.MAVLink_param_value_message((prefix + a).encode(), float(value),
                                                          9, 3, 0), (1, 1))
        for i, chunk in enumerate(_imu_chunks(f)):
            send(receipt[i], m.MAVLink_att_pos_mocap_message(usec[i], list(q[i]), *p[i],
                                                             [0.0] * 21), (255, 190))
            send(receipt[i], m.MAVLink_system_time_message(0, boot_ms[i]), (1, 1))
            row = [*rpm[i].tolist(), *[0] * (8 - k)]
            for cls, part in ((m.MAVLink_esc_telemetry_1_to_4_message, row[:4]),
                              (m.MAVLink_esc_telemetry_5_to_8_message, row[4:8])):
                send(receipt[i], cls([0] * 4, [0] * 4, [0] * 4, [0] * 4, part, [0] * 4), (1, 1))
            for j in chunk:
                send(receipt[i], imu[j], (1, 1))


def _tlog_imu(f: CleanFlight, name: str, m: object) -> list[object]:
    """One IMU message per sample: RAW_IMU (int16 mG, mrad/s, wrapping) or HIGHRES_IMU."""
    usec = _int((_BOOT + f.imu_t) * 1e6, 64, signed=False)
    gyro, accel = _imu_frd(f)
    if name == "HIGHRES_IMU":
        g, a = _f32(gyro), _f32(accel)
        return [m.MAVLink_highres_imu_message(  # type: ignore[attr-defined]
            usec[i], *a[i], *g[i], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0, 0b111111, 0)
            for i in range(len(usec))]
    g = np.array([_int(c, 16, signed=True) for c in (gyro * 1e3).T]).T.reshape(-1, 3)
    a = np.array([_int(c, 16, signed=True) for c in (accel / STANDARD_GRAVITY * 1e3).T]
                 ).T.reshape(-1, 3)
    return [m.MAVLink_raw_imu_message(usec[i], *a[i], *g[i], 0, 0, 0, 0, 0)  # type: ignore
            for i in range(len(usec))]


_DF_FORMATS = {
    "VISP": (130, "QQIffffffffBB", "TimeUS,RTimeUS,CTimeMS,PX,PY,PZ,Roll,Pitch,Yaw,PErr,AErr,"
                                   "Rst,Ign"),
    "ESC": (133, "QBffffcfcf", "TimeUS,Instance,RPM,RawRPM,Volt,Curr,Temp,CTot,MotTemp,Err"),
    "PARM": ARDUPILOT_MESSAGES["PARM"],
    "IMU": ARDUPILOT_MESSAGES["IMU"],
    "GYR": (58, "QBQfff", "TimeUS,I,SampleUS,GyrX,GyrY,GyrZ"),
    "ACC": (59, "QBQfff", "TimeUS,I,SampleUS,AccX,AccY,AccZ"),
}


def _euler_deg(q: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angles, deg, of NED/FRD quaternions (N, 4) (garbage in, garbage out)."""
    w, x, y, z = q.T
    with np.errstate(all="ignore"):
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.degrees(np.column_stack([roll, pitch, yaw]))


def _dataflash_imu(f: CleanFlight, name: str) -> list[list[tuple[str, tuple]]]:
    """Per IMU sample, its rows: IMU (instance 0, the filtered samples) or GYR and ACC
    (raw logging, at SampleUS)."""
    us = _int((_BOOT + f.imu_t) * 1e6, 64, signed=False)
    gyro, accel = (_f32(v) for v in _imu_frd(f))
    if name == "IMU":
        return [[("IMU", (us[i], 0, *gyro[i], *accel[i], 0, 0, 25.0, 1, 1, 1000, 1000))]
                for i in range(len(us))]
    return [[("GYR", (us[i], 0, us[i], *gyro[i])), ("ACC", (us[i], 0, us[i], *accel[i]))]
            for i in range(len(us))]


def write_dataflash_log(path: Path, f: CleanFlight, imu_message: str = "IMU") -> None:
    """VISP (motion capture), ESC rpm per instance and the IMU (``imu_message``: IMU, or
    GYR and ACC) with PARM INS_POS1_X/Y/Z, as ArduPilot 4.5 logs them."""
    p = _f32(enu_to_ned(f.position))
    euler = _f32(_euler_deg(quaternion_enu_to_ned(f.quaternion)))
    us = _int((_BOOT + f.t) * 1e6, 64, signed=False)
    ms = _int((_BOOT + f.t) * 1e3, 32, signed=False)
    rpm = _f32(f.rotor_speeds * _RAD_S_TO_RPM)
    rows: list[tuple[str, tuple]] = []
    imu = _dataflash_imu(f, imu_message) if f.has_imu else []
    if f.has_imu:
        for a, value in zip("XYZ", flu_to_frd(np.array(f.imu_position)), strict=True):
            rows.append(("PARM", (us[0] if us else 0, f"INS_POS1_{a}".encode(), value, 0.0)))
    for i, chunk in enumerate(_imu_chunks(f)):
        rows.append(("VISP", (us[i], 0, ms[i], *p[i], *euler[i], 0.01, 0.01, 0, 0)))
        for j, v in enumerate(rpm[i]):
            rows.append(("ESC", (us[i], j, v, 0.0, 0.0, 0.0, 0, 0.0, 0, 0.0)))
        for j in chunk:
            rows += imu[j]
    write_dataflash(path, _DF_FORMATS, rows)


_ULOG_FORMATS = {
    "vehicle_mocap_odometry": "uint64_t timestamp;uint64_t timestamp_sample;float[3] position;"
                              "float[4] q;uint8_t pose_frame;",
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;float esc_voltage;",
    "esc_status": "uint64_t timestamp;uint8_t esc_count;esc_report[8] esc;",
    "sensor_combined": PX4_TOPICS["sensor_combined"],
}


def write_ulog_log(path: Path, f: CleanFlight) -> None:
    """vehicle_mocap_odometry, esc_status rpm (int32) and sensor_combined (with
    EKF2_IMU_POS_X/Y/Z and IMU_INTEG_RATE), as PX4 logs them."""
    p, q = _f32(enu_to_ned(f.position)), _f32(quaternion_enu_to_ned(f.quaternion))
    us = _int((_BOOT + f.t) * 1e6, 64, signed=False)
    rpm = np.array([_int(c, 32, signed=True) for c in (f.rotor_speeds * _RAD_S_TO_RPM).T]).T
    k = f.rotor_speeds.shape[1]
    odometry = [{"timestamp": us[i], "timestamp_sample": us[i], "pose_frame": 1,
                 **{f"position[{a}]": float(p[i, a]) for a in range(3)},
                 **{f"q[{a}]": float(q[i, a]) for a in range(4)}} for i in range(f.t.size)]
    esc = [{"timestamp": us[i], "esc_count": k,
            **{f"esc[{j}].esc_rpm": int(rpm[i, j]) for j in range(k)}} for i in range(f.t.size)]
    topics: dict[str, list[dict[str, float]]] = {"vehicle_mocap_odometry": odometry,
                                                 "esc_status": esc}
    parameters: dict[str, float | int] = {}
    if f.has_imu:
        imu_us = _int((_BOOT + f.imu_t) * 1e6, 64, signed=False)
        gyro, accel = (_f32(v) for v in _imu_frd(f))
        topics["sensor_combined"] = [
            {"timestamp": imu_us[i], "accelerometer_timestamp_relative": 0,
             **{f"gyro_rad[{a}]": float(gyro[i, a]) for a in range(3)},
             **{f"accelerometer_m_s2[{a}]": float(accel[i, a]) for a in range(3)}}
            for i in range(len(imu_us))]
        parameters = {f"EKF2_IMU_POS_{a}": float(v) for a, v in zip(
            "XYZ", flu_to_frd(np.array(f.imu_position)), strict=True)}
        parameters["IMU_INTEG_RATE"] = 200
    write_ulog(path, _ULOG_FORMATS, topics, parameters=parameters)


#: Writers by format (file suffix): (path, flight) → None.
WRITERS: dict[str, Callable[..., None]] = {
    ".csv": write_pose_csv, ".tlog": write_tlog, ".ulg": write_ulog_log,
    ".bin": write_dataflash_log,
}
#: The formats, in a fixed order.
FORMATS: tuple[str, ...] = tuple(WRITERS)
#: The IMU messages a format's writer may carry (``imu_message``), the first by default.
IMU_MESSAGE_CHOICES: dict[str, tuple[str, ...]] = {".tlog": ("RAW_IMU", "HIGHRES_IMU"),
                                                   ".bin": ("IMU", "GYR")}


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
    flight = VALUE_MUTATIONS[value_mutation](clean, rng)
    if suffix in IMU_MESSAGE_CHOICES:  # drawn apart: the mutations' draws stay as they were
        choices = IMU_MESSAGE_CHOICES[suffix]
        message = choices[int(np.random.default_rng((seed, 1)).integers(0, len(choices)))]
        WRITERS[suffix](path, flight, imu_message=message)
    else:
        WRITERS[suffix](path, flight)
    if byte_mutation == "huge":
        with path.open("r+b") as out:  # sparse: the size without the disk space
            out.truncate(huge_bytes)
    elif byte_mutation != "none":
        path.write_bytes(BYTE_MUTATIONS[byte_mutation](path.read_bytes(), rng))
    return FuzzCase(path, suffix, value_mutation, byte_mutation, seed)
