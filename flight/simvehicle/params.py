"""Parameters of the simulated vehicle, and the MAVLink parameter protocol.

A handful of real-looking parameters per autopilot, some of which act on the
simulation (GUID_TIMEOUT, WPNAV_SPEED, DISARM_DELAY, SR0_* stream rates, COM_OF_LOSS_T,
COM_OBL_RC_ACT, the fence's FENCE_* and GF_*, …). As on the real autopilots, a PARAM_SET
is stored whatever its documented range; the code that reads a value bounds it where the
autopilot does (GUID_TIMEOUT below 0.1 s acts as 0.1 s). The protocol follows the
parameter microservice: PARAM_REQUEST_LIST answers every parameter with PARAM_VALUE
(``param_count``, ``param_index``), PARAM_REQUEST_READ one of them (by name, or by index
when ``param_index`` ≥ 0), and PARAM_SET of a known name stores the value and echoes it;
an unknown name gets no answer, as on ArduPilot.
ArduPilot sends integer parameters as their numeric value in the float field (C cast);
PX4 copies their bytes into it (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from mavsysid.flight.autopilot_modes import Autopilot
from mavsysid.flight.simvehicle.link import mavlink
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.motor_order import (
    ARDUPILOT_FRAME_IDS,
    FRAME_NAMES,
    PX4_AIRFRAME_GROUPS,
    layout_matches,
    output_order,
)

__all__ = ["Parameter", "ParameterProtocol", "ParameterTable", "default_parameters",
           "reported_frame"]

_INT_RANGES = {
    mavlink.MAV_PARAM_TYPE_UINT8: (0, 255, "<B"),
    mavlink.MAV_PARAM_TYPE_INT8: (-128, 127, "<b"),
    mavlink.MAV_PARAM_TYPE_UINT16: (0, 65535, "<H"),
    mavlink.MAV_PARAM_TYPE_INT16: (-32768, 32767, "<h"),
    mavlink.MAV_PARAM_TYPE_UINT32: (0, 2**32 - 1, "<I"),
    mavlink.MAV_PARAM_TYPE_INT32: (-(2**31), 2**31 - 1, "<i"),
}
_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32


@dataclass
class Parameter:
    """One parameter: name (≤ 16 characters), value, MAV_PARAM_TYPE."""

    name: str
    value: float
    type: int


class ParameterTable:
    """Ordered parameters with change listeners.

    Parameters
    ----------
    entries : iterable of (name, value, MAV_PARAM_TYPE)
    """

    def __init__(self, entries) -> None:
        self._params = [Parameter(n, float(v), t) for n, v, t in entries]
        self._index = {p.name: i for i, p in enumerate(self._params)}
        self._listeners: list[Callable[[str, float], None]] = []

    def __len__(self) -> int:
        return len(self._params)

    def __iter__(self) -> Iterator[Parameter]:
        return iter(self._params)

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> float:
        return self._params[self._index[name]].value

    def get(self, name: str, default: float) -> float:
        """Value of ``name``, or ``default`` when this autopilot has no such parameter."""
        i = self._index.get(name)
        return default if i is None else self._params[i].value

    def index(self, name: str) -> int | None:
        """Position of ``name`` in the table, None when unknown."""
        return self._index.get(name)

    def at(self, index: int) -> Parameter:
        """The parameter at ``index``."""
        return self._params[index]

    def add_listener(self, listener: Callable[[str, float], None]) -> None:
        """Call ``listener(name, value)`` after every change."""
        self._listeners.append(listener)

    def set(self, name: str, value: float) -> bool:
        """Store ``value`` (integers rounded and clamped to the type); False if unknown."""
        i = self._index.get(name)
        if i is None or value != value:  # unknown, or NaN
            return False
        p = self._params[i]
        if p.type in _INT_RANGES:
            lo, hi, _ = _INT_RANGES[p.type]
            value = float(min(max(round(value), lo), hi))
        else:
            value = struct.unpack("<f", struct.pack("<f", value))[0]  # stored as float32
        p.value = value
        for listener in self._listeners:
            listener(name, value)
        return True


def reported_frame(autopilot: Autopilot, config: VehicleConfig) -> str | None:
    """The frame the simulated autopilot says it flies: the vehicle file's ``[autopilot]
    frame`` in this autopilot's naming, else the frame its rotors sit like (None: none).

    The simulated vehicle's motor outputs are in the file's order (`output_order`), so a
    file that names a frame gets that frame's numbering, as from the real autopilot.

    Parameters
    ----------
    autopilot : Autopilot
        The personality simulated.
    config : VehicleConfig
        The vehicle file: its ``[autopilot] frame`` and rotor positions.
    """
    family = autopilot.name.lower()
    named = config.autopilot_frame
    if named is not None:
        return f"{family}:{named.split(':', 1)[1]}"
    return next((f for f in FRAME_NAMES if f.startswith(family + ":")
                 and layout_matches(config.rotor_positions, f)), None)


def _frame_entries(autopilot: Autopilot, config: VehicleConfig) -> list[tuple[str, float, int]]:
    """FRAME_CLASS and FRAME_TYPE (ArduPilot), or SYS_AUTOSTART and the control allocation's
    rotor geometry in output order (PX4), of `reported_frame`."""
    i8, i32 = mavlink.MAV_PARAM_TYPE_INT8, mavlink.MAV_PARAM_TYPE_INT32
    frame = reported_frame(autopilot, config)
    if autopilot is Autopilot.ARDUPILOT:
        frame_class, frame_type = ARDUPILOT_FRAME_IDS.get(
            frame or "", ({4: 1, 6: 2, 8: 3, 3: 7}.get(config.rotor_count, 1), 1))
        return [("FRAME_CLASS", frame_class, i8), ("FRAME_TYPE", frame_type, i8)]
    group = {v: k for k, v in PX4_AIRFRAME_GROUPS.items()}.get(frame or "", 4)
    order = output_order(config.rotor_positions, config.rotor_directions,
                         config.autopilot_frame)
    entries: list[tuple[str, float, int]] = [("SYS_AUTOSTART", 1000 * group + 1, i32),
                                             ("CA_ROTOR_COUNT", config.rotor_count, i32)]
    for i, j in enumerate(order):  # body FRD; KM > 0: counter-clockwise (PX4's sign)
        x, y, _z = config.rotor_positions[j]
        entries += [(f"CA_ROTOR{i}_PX", float(x), _REAL32), (f"CA_ROTOR{i}_PY", -float(y), _REAL32),
                    (f"CA_ROTOR{i}_KM", 0.05 * float(config.rotor_directions[j]), _REAL32)]
    return entries


def default_parameters(autopilot: Autopilot, config: VehicleConfig) -> ParameterTable:
    """The simulated parameter set of ``autopilot`` for the vehicle ``config``."""
    u8, i8, i16, i32 = (mavlink.MAV_PARAM_TYPE_UINT8, mavlink.MAV_PARAM_TYPE_INT8,
                        mavlink.MAV_PARAM_TYPE_INT16, mavlink.MAV_PARAM_TYPE_INT32)
    frame = _frame_entries(autopilot, config)
    if autopilot is Autopilot.ARDUPILOT:
        return ParameterTable([
            ("SYSID_THISMAV", 1, i16), *frame,
            ("GUID_TIMEOUT", 3.0, _REAL32), ("WPNAV_SPEED", 500.0, _REAL32),
            ("WPNAV_SPEED_UP", 250.0, _REAL32), ("WPNAV_SPEED_DN", 150.0, _REAL32),
            ("WPNAV_ACCEL", 250.0, _REAL32), ("LAND_SPEED", 50, i16),
            # Position-controller limits (mavsysid.flight.ground.autopilot_limits): the
            # simulated controller follows feed-forward without jerk, lean or yaw-rate
            # limits, so they say so (range maxima; 0 = none) and sim flights pass.
            ("ANGLE_MAX", 8000, i16), ("PSC_JERK_XY", 1000.0, _REAL32),
            ("PSC_JERK_Z", 1000.0, _REAL32), ("ATC_SLEW_YAW", 100000.0, _REAL32),
            ("ATC_RATE_Y_MAX", 0.0, _REAL32), ("ATC_ACCEL_Y_MAX", 0.0, _REAL32),
            ("DISARM_DELAY", 10, i8),
            # AC_Fence's parameters and defaults (mavsysid.flight.simvehicle.fence).
            ("FENCE_ENABLE", 0, i8), ("FENCE_TYPE", 7, i8), ("FENCE_ACTION", 1, i8),
            ("FENCE_ALT_MAX", 100.0, _REAL32), ("FENCE_RADIUS", 300.0, _REAL32),
            ("FENCE_MARGIN", 2.0, _REAL32),
            # The number of stored fence points, kept by the fence upload (read only).
            ("FENCE_TOTAL", 0, i8),
            # All pre-arm checks on (Copter's default; the sim does check before arming):
            # ground stations such as MAVProxy warn "Arming checks disabled" without it.
            ("ARMING_CHECK", 1, i32),
            ("MOT_THST_EXPO", config.motor.thrust_expo, _REAL32), ("BATT_CAPACITY", 5000, i32),
            ("SR0_EXT_STAT", 1, i16), ("SR0_POSITION", 3, i16), ("SR0_EXTRA1", 4, i16),
            ("SR0_EXTRA3", 1, i16), ("SR0_RAW_SENS", 0, i16),
            # Copter's DEFAULT_LOG_BITMASK; IMU_FAST (bit 18) logs the IMU at the loop rate
            # (mavsysid.flight.simvehicle.onboard_log).
            ("LOG_BITMASK", 176126, i32), ("LOG_DISARMED", 0, i8),
        ])
    return ParameterTable([
        ("MAV_SYS_ID", 1, i32), ("COM_OF_LOSS_T", 1.0, _REAL32), ("COM_OBL_RC_ACT", 0, i32),
        ("COM_DISARM_PRFLT", 10.0, _REAL32), ("MPC_XY_VEL_MAX", 12.0, _REAL32),
        ("MPC_Z_VEL_MAX_UP", 3.0, _REAL32), ("MPC_Z_VEL_MAX_DN", 1.5, _REAL32),
        ("MPC_ACC_HOR", 3.0, _REAL32), ("MPC_LAND_SPEED", 0.7, _REAL32),
        ("MIS_TAKEOFF_ALT", 2.5, _REAL32), ("NAV_DLL_ACT", 0, i32),
        *frame, ("SDLOG_MODE", 0, i32), ("BAT1_CAPACITY", 5000.0, _REAL32),
        ("COM_ARM_WO_GPS", 1, u8),
        # The geofence's parameters and defaults (navigator/geofence_params.c).
        ("GF_ACTION", 2, i32), ("GF_MAX_HOR_DIST", 0.0, _REAL32),
        ("GF_MAX_VER_DIST", 0.0, _REAL32),
    ])


class ParameterProtocol:
    """Answers the parameter messages of a ground station.

    Parameters
    ----------
    table : ParameterTable
    bytewise : bool
        Encode integer values bytewise (PX4) instead of by C cast (ArduPilot).
    """

    def __init__(self, table: ParameterTable, bytewise: bool) -> None:
        self.table = table
        self.bytewise = bytewise

    def encode(self, p: Parameter) -> float:
        """The float sent in PARAM_VALUE for ``p``."""
        if self.bytewise and p.type in _INT_RANGES:
            raw = struct.pack(_INT_RANGES[p.type][2], int(p.value)).ljust(4, b"\0")
            return struct.unpack("<f", raw)[0]
        return p.value

    def decode(self, p: Parameter, value: float) -> float:
        """The number meant by the float of a PARAM_SET for ``p``."""
        if self.bytewise and p.type in _INT_RANGES:
            fmt = _INT_RANGES[p.type][2]
            raw = struct.pack("<f", value)[:struct.calcsize(fmt)]
            return float(struct.unpack(fmt, raw)[0])
        return value

    def value_message(self, index: int):
        """PARAM_VALUE of the parameter at ``index``."""
        p = self.table.at(index)
        return mavlink.MAVLink_param_value_message(
            p.name.encode("ascii"), self.encode(p), p.type, len(self.table), index)

    def handle(self, msg) -> list:
        """The replies (PARAM_VALUE messages) to one parameter message."""
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            return [self.value_message(i) for i in range(len(self.table))]
        if kind == "PARAM_REQUEST_READ":
            index = msg.param_index if msg.param_index >= 0 else self.table.index(msg.param_id)
            if index is None or index >= len(self.table):
                return []
            return [self.value_message(index)]
        if kind == "PARAM_SET":
            index = self.table.index(msg.param_id)
            if index is None:
                return []
            self.table.set(msg.param_id, self.decode(self.table.at(index), msg.param_value))
            return [self.value_message(index)]
        return []
