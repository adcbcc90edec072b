"""Seeded mutations of good trajectory files, and what the streamer would send for one.

`mutated_files` turns base documents (built-in excitation figures, a ground descent) into
damaged or dangerous trajectory files: a widened box in the file with a position jump,
a shifted or enlarged flight, time compression and stretch, huge yaw-rate terms, NaN and
infinity, swapped or reversed segments, broken continuity, truncated JSON, wrong types.

`streamed_setpoints` runs the streamer's own setpoint path (`SetpointStream.fire` with
the session's limits, fed by the same sources as `mavsysid.flight.ground.streamer`: the
climb from the ground, the move to the start, the hold, the trajectory, the end hold)
against a recording stand-in for the link, and returns every setpoint it would send
(decoded from the message arguments, back in ENU) and whether the guard stopped it.
`unsafe` judges them independently of the code under test.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from mavsysid.flight.ground.setpoints import SmoothMove, UnsafeSetpoint, hold, trajectory_setpoint
from mavsysid.flight.ground.stream_control import SetpointStream
from mavsysid.flight.ground.telemetry_recorder import SetpointHistory
from mavsysid.flight.ground.trajectory_safety import flight_limits
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.frames import ned_to_enu, yaw_rate_ned_to_enu
from mavsysid.vehicle.trajectory import PiecewisePolynomial

__all__ = ["MUTATIONS", "SentSetpoint", "mutated_files", "scale_time", "streamed_setpoints",
           "unsafe"]

Doc = dict[str, Any]


def scale_time(doc: Doc, k: float) -> Doc:
    """The same path flown k times faster (k < 1: slower)."""
    for s in doc["segments"]:
        s["duration"] /= k
        s["position"] = [[c * k**n for n, c in enumerate(row)] for row in s["position"]]
        s["yaw"] = [c * k**n for n, c in enumerate(s["yaw"])]
    doc["duration"] = sum(s["duration"] for s in doc["segments"])
    return doc


def _widen_box(doc: Doc, rng: np.random.Generator) -> Doc:
    w = float(rng.uniform(10.0, 1000.0))
    doc["box"] = [-w, -w, -w, w, w, w]
    return doc


def _jump(doc: Doc, rng: np.random.Generator) -> Doc:
    """Widened box in the file and a segment moved 500 m away."""
    i = int(rng.integers(1, len(doc["segments"])))
    doc["segments"][i]["position"][int(rng.integers(3))][0] += float(rng.choice([-500, 500]))
    return _widen_box(doc, rng)


def _shift(doc: Doc, rng: np.random.Generator) -> Doc:
    """The whole flight moved (continuous), with the file's box moved along."""
    d = rng.uniform(-3.0, 3.0, 3)
    for s in doc["segments"]:
        for a in range(3):
            s["position"][a][0] += float(d[a])
    doc["start"] = [*(np.array(doc["start"][:3]) + d).tolist(), doc["start"][3]]
    return _widen_box(doc, rng)


def _enlarge(doc: Doc, rng: np.random.Generator) -> Doc:
    """The figure scaled about its start by 0.3–3 (continuous)."""
    k = float(rng.uniform(0.3, 3.0))
    p0 = np.array(doc["start"][:3])
    for s in doc["segments"]:
        for a in range(3):
            s["position"][a] = [c * k for c in s["position"][a]]
            s["position"][a][0] += float(p0[a] * (1.0 - k))
    return doc


def _compress(doc: Doc, rng: np.random.Generator) -> Doc:
    return scale_time(doc, float(rng.uniform(1.0, 30.0)))


def _stretch(doc: Doc, rng: np.random.Generator) -> Doc:
    return scale_time(doc, float(rng.uniform(0.2, 1.0)))


def _yaw_ramp(doc: Doc, rng: np.random.Generator) -> Doc:
    """A yaw-rate term r added throughout (continuous): r from 0.01 to 500 rad/s."""
    r = float(10.0 ** rng.uniform(-2.0, math.log10(500.0)))
    t0 = 0.0
    for s in doc["segments"]:
        y = s["yaw"] + [0.0] * max(0, 2 - len(s["yaw"]))
        y[0] += r * t0
        y[1] += r
        s["yaw"], t0 = y, t0 + s["duration"]
    return doc


def _yaw_term(doc: Doc, rng: np.random.Generator) -> Doc:
    """A huge yaw-rate coefficient in one segment."""
    s = doc["segments"][int(rng.integers(len(doc["segments"])))]
    s["yaw"][1] += float(rng.choice([-500.0, 500.0]))
    return doc


def _non_finite(doc: Doc, rng: np.random.Generator) -> str:
    s = doc["segments"][int(rng.integers(len(doc["segments"])))]
    s["position"][int(rng.integers(3))][int(rng.integers(len(s["position"][0])))] = float(
        rng.choice([math.nan, math.inf, -math.inf]))
    return json.dumps(doc)  # Python writes NaN and Infinity


def _swap(doc: Doc, rng: np.random.Generator) -> Doc:
    seg = doc["segments"]
    i, j = rng.choice(len(seg), 2, replace=False)
    seg[i], seg[j] = seg[j], seg[i]
    return doc


def _reverse(doc: Doc, rng: np.random.Generator) -> Doc:
    doc["segments"].reverse()
    return doc


def _kink(doc: Doc, rng: np.random.Generator) -> Doc:
    """One coefficient (order 1–3) of one segment perturbed by 1e-7 to 10."""
    s = doc["segments"][int(rng.integers(len(doc["segments"])))]
    s["position"][int(rng.integers(3))][int(rng.integers(1, 4))] += float(
        10.0 ** rng.uniform(-7.0, 1.0))
    return doc


def _truncate(doc: Doc, rng: np.random.Generator) -> str:
    text = json.dumps(doc)
    return text[: int(rng.integers(0, len(text)))]


def _wrong_type(doc: Doc, rng: np.random.Generator) -> Doc:
    bad = [None, True, "1.0", [], {}, [[1.0]], 10**400, -1.0, 0]
    target = int(rng.integers(6))
    value = bad[int(rng.integers(len(bad)))]
    s = doc["segments"][int(rng.integers(len(doc["segments"])))]
    if target == 0:
        s["duration"] = value
    elif target == 1:
        s["position"][int(rng.integers(3))] = value
    elif target == 2:
        s["yaw"] = value
    elif target == 3:
        doc["box"] = value
    elif target == 4:
        doc["start"] = value
    else:
        doc["segments"] = value
    return doc


def _drop_tail(doc: Doc, rng: np.random.Generator) -> Doc:
    """The last segments cut off (still continuous; ends moving)."""
    n = int(rng.integers(1, len(doc["segments"])))
    doc["segments"] = doc["segments"][:n]
    doc["duration"] = sum(s["duration"] for s in doc["segments"])
    return doc


def _limits_and_compress(doc: Doc, rng: np.random.Generator) -> Doc:
    """The file's own limits raised a hundredfold, and the flight compressed to match."""
    doc["limits"] = {k: v * 100.0 for k, v in doc["limits"].items()}
    return _compress(doc, rng)


MUTATIONS: dict[str, Callable[[Doc, np.random.Generator], Doc | str]] = {
    "jump": _jump, "shift": _shift, "enlarge": _enlarge, "compress": _compress,
    "stretch": _stretch, "yaw_ramp": _yaw_ramp, "yaw_term": _yaw_term,
    "non_finite": _non_finite, "swap": _swap, "reverse": _reverse, "kink": _kink,
    "truncate": _truncate, "wrong_type": _wrong_type, "drop_tail": _drop_tail,
    "limits_and_compress": _limits_and_compress,
}


def mutated_files(bases: Sequence[Doc], count: int, seed: int) -> list[tuple[str, str]]:
    """``count`` (name, JSON text) pairs: mutation i % len(MUTATIONS) of a random base."""
    rng = np.random.default_rng(seed)
    names = list(MUTATIONS)
    out = []
    for i in range(count):
        name = names[i % len(names)]
        doc = copy.deepcopy(bases[int(rng.integers(len(bases)))])
        result = MUTATIONS[name](doc, rng)
        text = result if isinstance(result, str) else json.dumps(result)
        out.append((f"{i:03d}_{name}", text))
    return out


@dataclass(frozen=True)
class SentSetpoint:
    """One setpoint as sent, back in ENU (m, m/s, m/s², rad/s)."""

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    yaw_rate: float


class _Link:
    """What `SetpointStream` uses of a `MavlinkLink`: a clock, a ticker slot, an encoder."""

    def __init__(self) -> None:
        self.t, self.ticker, self.sent = 0.0, None, []
        self.clock = self
        self.mav = self
        self.vehicle = type("Vehicle", (), {"system": 1, "component": 1})()

    def now(self) -> float:
        return self.t

    def set_ticker(self, ticker: Any) -> None:
        self.ticker = ticker

    def set_position_target_local_ned_encode(self, *args: float) -> tuple[float, ...]:
        return args

    def send(self, args: tuple[float, ...]) -> None:
        x, y, z, vx, vy, vz, ax, ay, az, _yaw, yaw_rate = args[5:16]
        self.sent.append(SentSetpoint(ned_to_enu(np.array([x, y, z])),
                                      ned_to_enu(np.array([vx, vy, vz])),
                                      ned_to_enu(np.array([ax, ay, az])),
                                      float(yaw_rate_ned_to_enu(yaw_rate))))


@dataclass
class _Run:
    link: _Link = field(default_factory=_Link)
    stopped_by_guard: str | None = None


def streamed_setpoints(trajectory: PiecewisePolynomial, config: VehicleConfig,
                       box: Sequence[float], rate: float = 50.0, limits: bool = True
                       ) -> tuple[list[SentSetpoint], str | None]:
    """Every setpoint the streamer would send for the whole flight, and the guard's refusal.

    The flight of `mavsysid.flight.ground.streamer` (PX4 order, which streams its climb):
    hold on the ground under the start, climb, move to the start, hold, the trajectory at
    ``rate``, hold at its end. ``limits=False``: without the last line of defence.
    """
    run = _Run()
    stream = SetpointStream(run.link, SetpointHistory(), rate)  # type: ignore[arg-type]
    stream.limits = flight_limits(config, box) if limits else None
    first = trajectory_setpoint(trajectory, 0.0)
    last = trajectory_setpoint(trajectory, trajectory.duration)
    ground = np.array([first.position[0], first.position[1], 0.0])
    top = np.array([*ground[:2], max(first.position[2], 0.3)])
    climb = SmoothMove.between(ground, 0.0, top, 0.0)
    to_start = SmoothMove.between(top, 0.0, np.array(first.position), first.yaw)
    phases = [(lambda _t: hold(ground, 0.0), 1.5), (climb.setpoint, climb.duration),
              (to_start.setpoint, to_start.duration),
              (lambda _t: hold(np.array(first.position), first.yaw), 1.0),
              (lambda t: trajectory_setpoint(trajectory, t), trajectory.duration),
              (lambda _t: hold(np.array(last.position), last.yaw), 2.0)]
    try:
        for source, duration in phases:
            stream.start(source)
            end = run.link.t + duration
            while run.link.t < end:
                stream.fire(run.link.t)
                run.link.t = stream.next_deadline()
    except UnsafeSetpoint as error:
        run.stopped_by_guard = str(error)
    return run.link.sent, run.stopped_by_guard


def unsafe(sent: Sequence[SentSetpoint], config: VehicleConfig, box: Sequence[float]
           ) -> list[str]:
    """The setpoints outside the box (its column down to the ground below it, for the
    climb) or beyond the vehicle's speed, thrust and yaw-rate limits; judged here from
    the vehicle's TOML values, not by the code under test."""
    lim, g = config.limits, 9.81
    t_max = min(lim.thrust_max_ratio * config.mass * g,
                config.rotor_count * config.parameters.c_T * lim.rotor_speed_max**2)
    lo = np.array([box[0], box[1], min(box[2], 0.0) - 0.5]) - 1e-6
    hi = np.array(box[3:]) + 1e-6
    out = []
    for i, s in enumerate(sent):
        thrust = float(np.linalg.norm(s.acceleration + [0.0, 0.0, g]))
        values = np.concatenate([s.position, s.velocity, s.acceleration, [s.yaw_rate]])
        if not np.all(np.isfinite(values)):
            out.append(f"#{i}: non-finite")
        elif np.any(s.position < lo) or np.any(s.position > hi):
            out.append(f"#{i}: position {s.position} outside the box")
        elif np.linalg.norm(s.velocity) > lim.speed_max * (1 + 1e-6):
            out.append(f"#{i}: speed {np.linalg.norm(s.velocity):.3f} m/s")
        elif thrust > t_max / config.mass * (1 + 1e-6):
            out.append(f"#{i}: thrust acceleration {thrust:.3f} m/s²")
        elif abs(s.yaw_rate) > lim.body_rate_max * (1 + 1e-6):
            out.append(f"#{i}: yaw rate {s.yaw_rate:.3f} rad/s")
    return out
