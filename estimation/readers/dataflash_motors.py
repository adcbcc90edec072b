"""Motor inputs of ArduPilot DataFlash logs, every generation: ESC rpm, else RCOU PWM.

Message definitions (``libraries/AP_Logger/LogStructure.h`` and its per-library
successors in ArduPilot's repository):

- ``ESC`` ``TimeUS,Instance,RPM,…`` (ArduPilot 4.x, one message per ESC; ``RPM`` a float
  in rpm, or ``e`` = int32 × 100 rpm in some 4.x versions). Bidirectional DShot and ESC
  telemetry both log here.
- ``ESC1``…``ESC8`` (ArduCopter 3.3–3.6): ``"Qcccc" TimeUS,RPM,Volt,Curr,Temp`` (earlier
  ``"Icccc" TimeMS,…``), written as ``rpm: (int16_t)(esc_rpm/10)``: with the ``c`` scale
  the field reads rpm / 1000. Later ``"QeCCcH" TimeUS,RPM,Volt,Curr,Temp,CTot`` (``e``,
  unit rpm, multiplier 1e-2): the field reads rpm.
- ``RCOU`` PWM, µs: ``"Ihhhhhhhh" TimeMS,Chan1..Chan8`` (ArduCopter 3.1/3.2),
  ``"Ihhhhhhhhhhhh" TimeMS,Ch1..Ch12``, ``"Q{h,H}×14" TimeUS,C1..C14`` (3.3 on). ``RCO2``
  (C15..C18) and ``RCO3`` (C19..C32) are not read: the motors are taken as the leading
  output channels.
"""

from __future__ import annotations

import re
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.estimation.readers.dataflash_messages import (
    Messages,
    field_array,
    field_format,
    message_times,
)
from mavsysid.estimation.readers.streams import Series
from mavsysid.vehicle.constants import RPM_TO_RAD_S

from mavsysid.errors import LogFormatError

__all__ = ["ESC_TYPES", "MOTOR_TYPES", "esc_rotors", "rcou_channels"]

#: Per-ESC messages of ArduCopter 3.3–3.6, ESCn = ESC instance n − 1.
ESC_TYPES = tuple(f"ESC{i}" for i in range(1, 9))
#: Every message type the motor readers use.
MOTOR_TYPES = ("ESC", *ESC_TYPES, "RCOU")

# RCOU output channel fields across generations: Chan1.., Ch1.., C1...
_CHANNEL = re.compile(r"^(?:Chan|Ch|C)(\d+)$")
# ESCn RPM logged as int16 rpm/10 under the "c" (× 0.01) format: it reads rpm / 1000.
_CENTI_DECA_RPM = 1000.0


def _rpm(rows: list[Any]) -> np.ndarray:
    """The RPM field in rpm, shape (N, 1), undoing the old ESCn int16 rpm/10 encoding."""
    rpm = field_array(rows, ["RPM"])
    if rows[0].get_type() in ESC_TYPES and field_format(rows, "RPM") == "c":
        rpm = rpm * _CENTI_DECA_RPM
    return rpm


def esc_rotors(path: Path, found: Messages) -> tuple[Series, ...] | None:
    """One rotor-speed series per ESC instance 0..m−1, rad/s; None without ESC messages.

    Raises
    ------
    LogFormatError
        A gap in the instance numbers (rotor i missing while higher rotors report).
    """
    by_instance: dict[int, list[Any]] = defaultdict(list)
    for m in found.get("ESC", []):
        by_instance[int(m.Instance)].append(m)
    if not by_instance:
        for i, name in enumerate(ESC_TYPES):
            if found.get(name):
                by_instance[i] = found[name]
    if not by_instance:
        return None
    count = max(by_instance) + 1
    missing = [i + 1 for i in range(count) if i not in by_instance]
    if missing:
        raise LogFormatError(f"{path}: ESC rpm of rotor(s) {', '.join(map(str, missing))} "
                             f"missing while rotors up to {count} report theirs")
    return tuple(Series(message_times(by_instance[i]), _rpm(by_instance[i]) * RPM_TO_RAD_S,
                        f"ESC {i} rpm") for i in range(count))


def rcou_channels(rows: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    """RCOU times (s) and PWM (µs), channels in output order, whatever their field names.

    Returns
    -------
    t : ndarray, shape (N,)
    pwm : ndarray, shape (N, k)
        Output channels 1..k (``Chan1``, ``Ch1`` or ``C1`` onwards).
    """
    numbered = sorted((int(match.group(1)), name) for name in rows[0].get_fieldnames()
                      if (match := _CHANNEL.match(name)))
    names = [name for _, name in numbered]
    return message_times(rows), field_array(rows, names)
