"""An autopilot log's motor outputs as the vehicle config's rotors: which, how many, in what order.

Every autopilot reader calls the two functions here:

- `motor_output_count` on a block of output slots (RCOU C1..C14, SERVO_OUTPUT_RAW
  servo1..16, actuator_outputs output[0..noutputs−1]): logs carry 8, 14 or 16 slots of
  which only some drive motors;
- `rotors_in_config_order` on the rotor-speed series it found: it refuses more motor
  outputs than the vehicle has rotors unless the vehicle names its autopilot frame, and
  puts the outputs into the config's rotor order through that frame
  (`mavsysid.vehicle.motor_order`). Fewer outputs than rotors are left to the checks
  (`mavsysid.estimation.readers.checks`), which refuse them.
"""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.readers.streams import Series
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.motor_order import AUTOPILOT_FRAMES, MotorOrderError, output_to_rotor

from mavsysid.errors import ConfigError, LogFormatError

__all__ = ["motor_output_count", "rotors_in_config_order"]


def motor_output_count(values: np.ndarray) -> int:
    """How many leading output slots drive motors.

    A motor output moves in flight; an unused slot, or a servo held still, sits at one
    value (0, NaN, its trim or the disarmed PWM) throughout. So the count is the leading
    slots that take more than one value; in a log where nothing moves (the vehicle never
    armed) it is the leading slots that are ever non-zero, as motors idle at a PWM > 0.

    Parameters
    ----------
    values : ndarray, shape (N, m)
        The slots' samples (PWM, thrust or rpm), NaN where a slot is unused.

    Returns
    -------
    int
        The number of leading slots taken as motor outputs, 0 to m.
    """
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return 0
    finite = np.isfinite(values)
    low = np.where(finite, values, np.inf).min(axis=0)
    high = np.where(finite, values, -np.inf).max(axis=0)
    # A slot NaN at times and a number at others moves too (PX4: NaN is a stopped motor).
    moving = (high > low) | (finite.any(axis=0) & ~finite.all(axis=0))
    if not moving.any():
        moving = (finite & (values != 0.0)).any(axis=0)
    return int(np.argmin(moving)) if not moving.all() else values.shape[1]


def _frames_with(count: int) -> str:
    names = [name for name, layout in AUTOPILOT_FRAMES.items() if len(layout) == count]
    return ", ".join(f'"{n}"' for n in names) if names else "a frame of the log's autopilot"


def rotors_in_config_order(source: str, rotors: tuple[Series, ...],
                           vehicle: VehicleConfig) -> tuple[tuple[Series, ...], list[str]]:
    """The log's motor-output series, put into the config's rotor order.

    Parameters
    ----------
    source : str
        The log, for messages.
    rotors : tuple of Series
        Rotor speeds (rad/s) of motor outputs 1..m, their columns concatenated in output
        order, as the reader found them.
    vehicle : VehicleConfig
        The vehicle; its ``autopilot_frame`` (or None: output i is rotor i).

    Returns
    -------
    rotors : tuple of Series
        The same series when no frame is named (or m < k), else columns 1..k in the
        config's rotor order (one series per column when the outputs span several series).
    notes : list of str
        A note when outputs beyond the frame's were left out.

    Raises
    ------
    LogFormatError
        More motor outputs than rotors and no autopilot frame named.
    ConfigError
        A vehicle built in code whose rotors do not match its named frame.
    """
    columns = [(s, c) for s in rotors for c in range(s.values.shape[1])]
    m, k, frame = len(columns), vehicle.rotor_count, vehicle.autopilot_frame
    if m > k and frame is None:
        labels = ", ".join(dict.fromkeys(s.label for s in rotors))
        raise LogFormatError(
            f"{source}: the log has {m} motor outputs ({labels}), vehicle {vehicle.name} has "
            f"{k} rotors; name the autopilot frame in the vehicle file ([autopilot] frame = "
            f"{_frames_with(k)}) or use a vehicle with {m} rotors")
    if frame is None or m < k:
        return rotors, []
    try:
        order = output_to_rotor(vehicle.rotor_positions, vehicle.rotor_directions, frame)
    except MotorOrderError as exc:
        raise ConfigError(f"{vehicle.source or vehicle.name}: [autopilot].frame: {exc}") from None
    notes = ([f"{source}: motor outputs {k + 1}..{m} are not motors of {frame}; left out"]
             if m > k else [])
    inverse = np.argsort(order)  # config rotor j is output inverse[j]
    if len(rotors) == 1:
        only = rotors[0]
        return (Series(only.t, only.values[:, inverse], f"{only.label} ({frame} order)"),), notes
    ordered = []
    for j in inverse:
        series, column = columns[j]
        ordered.append(Series(series.t, series.values[:, [column]],
                              f"{series.label} output {j + 1}"))
    return tuple(ordered), notes
