"""Autopilot parameters changed for one flight, and put back afterwards.

`ParameterSession` reads parameters (PARAM_REQUEST_READ → PARAM_VALUE), sets them
(PARAM_SET, confirmed by the PARAM_VALUE the autopilot echoes), remembers the value each
one had before the flight the first time it is set, and `restore` puts every changed
parameter back, newest first, reporting problems instead of raising: it runs while a
flight ends, fails or is interrupted, when one more exception would hide the first.

Encoding: ArduPilot carries integer parameters as their numeric value in PARAM_VALUE's
float (a C cast); PX4 copies the integer's bytes into it
(MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE). Both are decoded here by the autopilot
family of the vehicle's heartbeat and the PARAM_VALUE's ``param_type``, so callers see
numbers. All waits go through `MavlinkLink.poll`, so a setpoint stream keeps flowing.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Collection, Sequence
from typing import Any

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.ground.mavlink_link import MavlinkLink

from mavsysid.errors import JobFailedError

__all__ = ["ParameterSession"]

#: MAV_PARAM_TYPE → struct format of the integer types (the float32 type is 9).
_INT_FORMATS = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}
_REAL32 = 9
#: PARAM_REQUEST_READ / PARAM_SET are resent this often while unanswered, streamer s.
_RESEND = 1.0


def _float32(value: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


def _same(a: float, b: float) -> bool:
    """Equal as the autopilot stores them (float32; integers rounded)."""
    return math.isclose(_float32(a), _float32(b), rel_tol=1e-6, abs_tol=1e-6)


class ParameterSession:
    """Parameters read, changed and restored over a `MavlinkLink` (see the module docstring).

    Parameters
    ----------
    link : MavlinkLink
        Connected, with the vehicle's heartbeat seen.
    set_timeout : float
        How long `set` waits for the echoed PARAM_VALUE, streamer s (resent every 1 s).
    dry_run : bool
        `set` writes nothing: it reads the value before and lists the change in `planned`.
    """

    def __init__(self, link: MavlinkLink, set_timeout: float = 3.0,
                 dry_run: bool = False) -> None:
        self.link = link
        self.set_timeout = set_timeout
        self.dry_run = dry_run
        self._planned: dict[str, tuple[float, float]] = {}
        self._values: dict[str, tuple[float, int]] = {}  # name → (value, MAV_PARAM_TYPE)
        self._changed: dict[str, tuple[float, float]] = {}  # in the order first set
        self._restored: dict[str, tuple[float, float]] = {}
        link.add_listener(self._on_message)

    # --- receiving ---------------------------------------------------------------------------

    def _bytewise(self) -> bool:
        return self.link.vehicle.autopilot is Autopilot.PX4

    def _decode(self, value: float, param_type: int) -> float:
        fmt = _INT_FORMATS.get(param_type)
        if fmt is None:
            return float(value)
        if self._bytewise():
            raw = struct.pack("<f", value)[:struct.calcsize(fmt)]
            return float(struct.unpack(fmt, raw)[0])
        return float(round(value))

    def _encode(self, value: float, param_type: int) -> float:
        fmt = _INT_FORMATS.get(param_type)
        if fmt is None:
            return float(value)
        if self._bytewise():
            bits = 8 * struct.calcsize(fmt)
            lo, hi = (0, 2**bits - 1) if fmt.isupper() else (-(2**(bits - 1)), 2**(bits - 1) - 1)
            raw = struct.pack(fmt, min(max(round(value), lo), hi)).ljust(4, b"\0")
            return float(struct.unpack("<f", raw)[0])
        return float(round(value))

    def _on_message(self, msg: Any, _t: float) -> None:
        if msg.get_type() != "PARAM_VALUE":
            return
        name = msg.param_id.rstrip("\0") if isinstance(msg.param_id, str) else (
            msg.param_id.decode("ascii", "replace").rstrip("\0"))
        self._values[name] = (self._decode(msg.param_value, msg.param_type), msg.param_type)

    def _request(self, name: str) -> None:
        v = self.link.vehicle
        self.link.send(self.link.mav.param_request_read_encode(
            v.system, v.component, name.encode("ascii"), -1))

    # --- the API -----------------------------------------------------------------------------

    def read(self, names: Sequence[str], timeout: float = 5.0) -> dict[str, float]:
        """Fresh values of ``names`` from the vehicle.

        Parameters
        ----------
        names : sequence of str
            Parameter names (≤ 16 characters).
        timeout : float
            How long to wait for all of them, streamer s (requests resent every 1 s).

        Returns
        -------
        dict
            name → value for those the vehicle answered; a name it lacks is absent.
        """
        wanted = list(dict.fromkeys(names))
        for name in wanted:
            self._values.pop(name, None)
        clock = self.link.clock
        deadline = clock.now() + timeout
        while True:
            missing = [n for n in wanted if n not in self._values]
            if not missing or clock.now() >= deadline:
                break
            for name in missing:
                self._request(name)
            resend = min(deadline, clock.now() + _RESEND)
            while clock.now() < resend and any(n not in self._values for n in missing):
                self.link.poll(0.05)
        return {n: self._values[n][0] for n in wanted if n in self._values}

    def set(self, name: str, value: float) -> None:
        """Set ``name`` to ``value`` for the flight and confirm it.

        The first time a name is set, its value before (read now) is remembered for
        `restore`. Setting a parameter to the value it already has changes nothing.

        Raises
        ------
        JobFailedError
            The vehicle has no such parameter, did not echo the change within
            ``set_timeout``, or kept another value (one line naming both values).
        """
        if self.dry_run:
            self._plan(name, value)
            return
        if name not in self._changed:
            before = self.read([name], timeout=self.set_timeout)
            if name not in before:
                raise JobFailedError(f"parameter {name}: the vehicle did not answer for it "
                                     f"within {self.set_timeout:g} s (no such parameter?)")
            if _same(before[name], value):
                return
            self._changed[name] = (before[name], float(value))
            self._restored.pop(name, None)
        else:
            self._changed[name] = (self._changed[name][0], float(value))
        self._write(name, value)

    def _plan(self, name: str, value: float) -> None:
        """Dry run: what `set` would change, with the value now; nothing is written."""
        before = self._planned[name][0] if name in self._planned else self.read(
            [name], timeout=self.set_timeout).get(name)
        if before is None:
            raise JobFailedError(f"parameter {name}: the vehicle did not answer for it "
                                 f"within {self.set_timeout:g} s (no such parameter?)")
        if _same(before, value):
            self._planned.pop(name, None)
            return
        self._planned[name] = (before, float(value))

    @property
    def planned(self) -> dict[str, tuple[float, float]]:
        """Dry run: name → (value now, value the flight would set), in the order set."""
        return dict(self._planned)

    def _write(self, name: str, value: float) -> None:
        """PARAM_SET until the echo shows ``value``; JobFailedError if it never does."""
        param_type = self._values.get(name, (0.0, _REAL32))[1]
        v = self.link.vehicle
        clock = self.link.clock
        deadline = clock.now() + self.set_timeout
        self._values.pop(name, None)
        while clock.now() < deadline:
            self.link.send(self.link.mav.param_set_encode(
                v.system, v.component, name.encode("ascii"), self._encode(value, param_type),
                param_type))
            resend = min(deadline, clock.now() + _RESEND)
            while clock.now() < resend and name not in self._values:
                self.link.poll(0.05)
            if name in self._values:
                held = self._values[name][0]
                if _same(held, value):
                    return
                raise JobFailedError(f"parameter {name}: set to {value:g}, but the vehicle "
                                     f"keeps {held:g}")
        raise JobFailedError(f"parameter {name}: setting {value:g} was not confirmed by the "
                             f"vehicle within {self.set_timeout:g} s")

    @property
    def changed(self) -> dict[str, tuple[float, float]]:
        """name → (original value, flight value) of every parameter changed and not yet
        restored, in the order first set."""
        return dict(self._changed)

    @property
    def restored(self) -> dict[str, tuple[float, float]]:
        """name → (original value, flight value) of every parameter `restore` put back."""
        return dict(self._restored)

    def restore(self, keep: Collection[str] = ()) -> list[str]:
        """Put every changed parameter back to its original value, newest first.

        Parameters
        ----------
        keep : collection of str
            Names to leave at their flight value for now (they stay in `changed`).

        Returns
        -------
        list of str
            One line per parameter that could not be restored (empty when all were);
            never raises, so that it can run while a failure is being handled. Those
            parameters stay in `changed`.
        """
        problems: list[str] = []
        for name in reversed(list(self._changed)):
            if name in keep:
                continue
            original, flight = self._changed[name]
            try:
                self._write(name, original)
            except (JobFailedError, OSError, ValueError) as error:
                problems.append(f"could not restore {name} to {original:g}: {error}")
                continue
            del self._changed[name]
            self._restored[name] = (original, flight)
        return problems
