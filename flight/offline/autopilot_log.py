"""A simulated flight written as an autopilot writes its log: the flight's common part.

`LoggedFlight` is what an autopilot would have logged of a simulated flight: the measured
pose (what motion capture or the autopilot's estimator reports), world velocity, the
actual rotor speeds (what ESC telemetry reports) and the commanded ones (what the
autopilot sends to its outputs), its IMU's readings (before the autopilot's own
filtering), and the flight's phases. `write_ardupilot_log`
(`mavsysid.flight.offline.ardupilot_log`) and `write_px4_log`
(`mavsysid.flight.offline.px4_log`) choose what the autopilot logs of it, when, and
write it with the format's module (`mavsysid.formats.dataflash`, `mavsysid.formats.ulog`)
as a ``.bin`` and a ``.ulg``.

Motor numbering: an autopilot numbers its motors its own way per frame (ArduPilot's
``AP_MotorsMatrix``, PX4's airframe geometry), not in the vehicle config's rotor order.
``motor_order[i]`` is the config rotor (0-based) that the autopilot's motor i + 1
drives; a log written with it has ESC instance i / output i + 1 = that rotor.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mavsysid.flight.offline.phased_flight import FlightPhases
from mavsysid.formats.flight_dir import read_meta
from mavsysid.formats.flight_log import TRUTH_COLUMNS, command_columns
from mavsysid.formats.poselog import read_pose_log
from mavsysid.vehicle.rotation import quat_to_matrix

__all__ = ["LoggedFlight", "check_motor_order", "lowpass", "microsecond_stamp", "sample_indices"]


@dataclass(frozen=True)
class LoggedFlight:
    """What an autopilot could log of one flight, at the simulator's log rate (S samples).

    Attributes
    ----------
    t : ndarray, shape (S,)
        s since the flight started.
    position : ndarray, shape (S, 3)
        Measured position, m, world ENU.
    quaternion : ndarray, shape (S, 4)
        Measured attitude [w, x, y, z], body FLU → world ENU.
    velocity : ndarray, shape (S, 3)
        World velocity, m/s, ENU.
    rotor_speeds : ndarray, shape (S, k)
        Actual rotor speeds, rad/s, in the config's rotor order.
    commands : ndarray, shape (S, k)
        Commanded rotor speeds, rad/s, in the config's rotor order.
    phases : FlightPhases or None
        Take-off, calibration part and landing, s on the same clock as ``t``; the modes
        logged follow from them unless ``mode_changes`` gives the modes themselves.
    gyro : ndarray, shape (S, 3), or None
        The IMU's gyro, rad/s, body FLU, as sampled (noise and bias, no filter).
    accel : ndarray, shape (S, 3), or None
        The IMU's specific force, m/s², body FLU, as sampled.
    imu_position : tuple of 3 float or None
        The IMU's offset from the centre of gravity, m, body FLU, as the vehicle's
        parameters state it (written as INS_POS1_* / EKF2_IMU_POS_*); None: not stated.
    mode_changes : tuple of (float, str), or None
        The modes flown, (s, the autopilot's mode name) at each change; None: the modes
        of ``phases``.
    """

    t: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    velocity: np.ndarray
    rotor_speeds: np.ndarray
    commands: np.ndarray
    phases: FlightPhases | None
    gyro: np.ndarray | None = None
    accel: np.ndarray | None = None
    imu_position: tuple[float, float, float] | None = None
    mode_changes: tuple[tuple[float, str], ...] | None = None

    def modes(self, names: tuple[str, str, str]) -> list[tuple[float, str]]:
        """The modes flown, (s, name): ``mode_changes``, else the three of ``phases``.

        Parameters
        ----------
        names : (str, str, str)
            The autopilot's names of the take-off, calibration and landing modes.
        """
        if self.mode_changes is not None:
            return list(self.mode_changes)
        if self.phases is None:
            return []
        p = self.phases
        return list(zip((p.takeoff, p.calibration_start, p.calibration_end), names,
                        strict=True))

    @property
    def rotor_count(self) -> int:
        """Number of rotors k."""
        return int(self.rotor_speeds.shape[1])

    @classmethod
    def from_flight_dir(cls, directory: Path, rotor_count: int,
                        phases: FlightPhases) -> LoggedFlight:
        """The flight recorded by the offline simulator in ``directory``.

        Parameters
        ----------
        directory : Path
            A simulated flight directory: ``pose.csv`` (measured pose, rotor speeds and
            IMU, if recorded), ``truth.csv`` (true body velocity and commanded rotor
            speeds) and ``meta.json`` (the IMU's position, in its truth).
        rotor_count : int
            k.
        phases : FlightPhases
            The flight's phases (from `mavsysid.flight.offline.phased_flight`).

        Returns
        -------
        LoggedFlight
        """
        pose = read_pose_log(Path(directory) / "pose.csv", rotor_count)
        truth = read_pose_log(Path(directory) / "truth.csv", rotor_count)
        body = np.column_stack([truth.extra[c] for c in TRUTH_COLUMNS[:3]])
        velocity = np.einsum("nij,nj->ni", quat_to_matrix(truth.quaternion), body)
        commands = np.column_stack([truth.extra[c] for c in command_columns(rotor_count)])
        imu = read_meta(Path(directory) / "meta.json").get("truth", {}).get("imu", {})
        position = imu.get("position_m") if pose.gyro is not None else None
        return cls(pose.t, pose.position, pose.quaternion, velocity, pose.rotor_speeds,
                   commands, phases, pose.gyro, pose.accel,
                   None if position is None else (position[0], position[1], position[2]))


def microsecond_stamp(boot_time: float) -> Callable[[float], int]:
    """Flight time (s) → the autopilot's timestamp: µs since its boot, ``boot_time`` s before
    the flight starts (both ArduPilot's ``TimeUS`` and PX4's ``timestamp`` count so).

    Parameters
    ----------
    boot_time : float
        Seconds from the autopilot's boot to the flight's start.
    """
    def stamp(t: float) -> int:
        return round((boot_time + t) * 1e6)

    return stamp


def check_motor_order(motor_order: Sequence[int], rotor_count: int) -> np.ndarray:
    """``motor_order`` as an index array, checked to be a permutation of the k rotors.

    Parameters
    ----------
    motor_order : sequence of int
        Config rotor (0-based) of the autopilot's motor 1, 2, ….
    rotor_count : int
        k.

    Returns
    -------
    ndarray of int, shape (k,)

    Raises
    ------
    ValueError
        Not a permutation of 0 … k − 1.
    """
    order = np.asarray(motor_order, dtype=int)
    if sorted(order.tolist()) != list(range(rotor_count)):
        raise ValueError(f"motor order {list(motor_order)}: expected a permutation of the "
                         f"{rotor_count} rotors 0 … {rotor_count - 1}")
    return order


def sample_indices(t: np.ndarray, rate: float, phase: float = 0.0) -> np.ndarray:
    """Indices of the samples an autopilot logging at ``rate`` would write.

    Parameters
    ----------
    t : ndarray, shape (S,)
        The flight's sample times, s, increasing.
    rate : float
        Logging rate, Hz (at most the flight's own rate to be met exactly).
    phase : float
        s after ``t[0]`` of the first logged sample: topics of one log are not written
        at the same instants.

    Returns
    -------
    ndarray of int
        Distinct indices into ``t``, the first sample at or after each logging instant.
    """
    instants = np.arange(t[0] + phase, t[-1], 1.0 / rate)
    return np.unique(np.clip(np.searchsorted(t, instants - 1e-9), 0, t.size - 1))


def lowpass(t: np.ndarray, values: np.ndarray, cutoff_hz: float) -> np.ndarray:
    """An autopilot's IMU low-pass: a 2-pole Butterworth filter, causal, from steady state.

    ArduPilot filters each IMU sample with a 2-pole low-pass at INS_GYRO_FILTER /
    INS_ACCEL_FILTER Hz (``LowPassFilter2p``) before its IMU message and its controllers
    see it; this is that filter at the flight's sample rate. Cutoff 0 is no filter, as in
    ArduPilot.

    Parameters
    ----------
    t : ndarray, shape (S,)
        Sample times, s, evenly spaced.
    values : ndarray, shape (S, m)
        The samples.
    cutoff_hz : float
        Hz, below half the sample rate; 0: returned unfiltered.

    Returns
    -------
    ndarray, shape (S, m)
    """
    if cutoff_hz <= 0.0 or t.size < 2:
        return np.array(values, dtype=float)
    rate = (t.size - 1) / (t[-1] - t[0])
    # scipy.signal takes a second to import: the simulator's start should not pay it.
    from scipy.signal import butter, lfilter, lfilter_zi

    b, a = butter(2, cutoff_hz, fs=rate)
    start = lfilter_zi(b, a)[:, None] * np.asarray(values[:1], dtype=float)
    return lfilter(b, a, values, axis=0, zi=start)[0]
