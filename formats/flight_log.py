"""Recording a flight: ``pose.csv``, ``truth.csv`` (simulated flights) and ``meta.json``.

With an IMU, ``pose.csv`` holds what it measured and ``truth.csv`` the true (noise- and
bias-free) gyro and specific force at the IMU, both in the pose log's IMU columns (body
FLU).

Every row reaches the OS as soon as it is recorded, and ``meta.json`` is written at the
start (status ``recording``) and rewritten at the end (``complete`` or ``aborted``), so an
interrupted flight keeps everything recorded up to the interruption.
"""

from __future__ import annotations

import datetime as _dt
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from mavsysid.formats.flight_dir import write_meta
from mavsysid.formats.poselog import PoseLogWriter
from mavsysid.vehicle.config import VehicleConfig, vehicle_to_toml
from mavsysid.vehicle.dynamics import ATT, POS, RATE, VEL

__all__ = ["REFERENCE_COLUMNS", "TRUTH_COLUMNS", "FlightRecorder", "command_columns",
           "software_version"]

#: Extra columns of ``pose.csv``: the controller's reference position (m, ENU) and yaw (rad).
REFERENCE_COLUMNS = ("x_ref", "y_ref", "z_ref", "yaw_ref")
#: Extra columns of ``truth.csv`` before the commands: the true body velocity (m/s, FLU)
#: and body rates (rad/s, FLU).
TRUTH_COLUMNS = ("vx_body", "vy_body", "vz_body", "wx", "wy", "wz")


def command_columns(k: int) -> tuple[str, ...]:
    """The last extra columns of ``truth.csv``: the commanded rotor speeds, rad/s.

    Parameters
    ----------
    k : int
        Number of rotors.

    Returns
    -------
    tuple of str
        ``("n_cmd1", …, "n_cmdk")``, in the config's rotor order.
    """
    return tuple(f"n_cmd{i + 1}" for i in range(k))


def software_version() -> str:
    """The installed mavsysid version, or ``0+unknown`` when run from a bare checkout."""
    try:
        return metadata.version("mavsysid")
    except metadata.PackageNotFoundError:
        return "0+unknown"


class FlightRecorder:
    """Writes one flight directory.

    Parameters
    ----------
    directory : Path
        The flight directory (created if missing).
    config : VehicleConfig
        The vehicle; its full TOML is stored in the metadata.
    rotor_count : int
        k, the number of rotor-speed columns.
    imu : bool
        Record an IMU: every `record` then takes ``imu`` (and, simulated, ``true_imu``).
    """

    def __init__(self, directory: Path, config: VehicleConfig, rotor_count: int,
                 imu: bool = False) -> None:
        self.directory = Path(directory)
        self.config = config
        self.rotor_count = rotor_count
        self.imu = imu
        self._meta: dict[str, Any] = {}
        self._pose: PoseLogWriter | None = None
        self._truth: PoseLogWriter | None = None
        self._cmd_columns = command_columns(rotor_count)

    @property
    def pose_path(self) -> Path:
        """Path of the pose log."""
        return self.directory / "pose.csv"

    def start(self, meta: dict[str, Any]) -> None:
        """Open the logs and write the metadata with status ``recording``.

        Parameters
        ----------
        meta : dict
            The flight metadata (``meta.json``).
        """
        self.directory.mkdir(parents=True, exist_ok=True)
        self._meta = {
            "format": "mavsysid-flight",
            "format_version": 1,
            "software": {"name": "mavsysid", "version": software_version()},
            "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "vehicle": {
                "name": self.config.name,
                "source": self.config.source,
                "config_toml": vehicle_to_toml(self.config),
            },
            "noise": {
                "position_sigma_m": self.config.noise.position_sigma,
                "attitude_sigma_rad": self.config.noise.attitude_sigma,
                "rotor_speed_sigma_rad_s": self.config.noise.rotor_speed_sigma,
                **({"gyro_sigma_rad_s": self.config.noise.gyro_sigma,
                    "accel_sigma_m_s2": self.config.noise.accel_sigma} if self.imu else {}),
            },
            "files": {"pose": "pose.csv"},
            **meta,
            "status": "recording",
            "samples": 0,
        }
        self._pose = PoseLogWriter(self.pose_path, self.rotor_count, REFERENCE_COLUMNS,
                                   imu=self.imu)
        if meta.get("simulated"):
            self._meta["files"]["truth"] = "truth.csv"
            self._truth = PoseLogWriter(
                self.directory / "truth.csv", self.rotor_count, TRUTH_COLUMNS + self._cmd_columns,
                imu=self.imu)
        write_meta(self.directory / "meta.json", self._meta)

    def record(
        self, t: float, position: np.ndarray, quaternion: np.ndarray, rotor_speeds: np.ndarray,
        reference: np.ndarray, true_state: np.ndarray | None = None,
        true_rotor_speeds: np.ndarray | None = None, commands: np.ndarray | None = None,
        imu: tuple[np.ndarray, np.ndarray] | None = None,
        true_imu: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Record one sample: measured pose and rotor speeds, reference, and the truth.

        ``reference`` is a controller reference row (p, v, a, yaw, …); its position and yaw
        go into the pose log.

        Parameters
        ----------
        t : float
            Sample time, s.
        position : ndarray, shape (3,)
            Measured position, m, world ENU.
        quaternion : ndarray, shape (4,)
            Measured attitude [w, x, y, z], body FLU → world ENU.
        rotor_speeds : ndarray, shape (k,)
            Logged rotor speeds, rad/s.
        reference : ndarray
            Controller reference row (position m, velocity m/s, acceleration m/s², yaw rad, …).
        true_state : ndarray, shape (13,), optional
            True state [p, v_B, q, ω] for ``truth.csv``.
        true_rotor_speeds : ndarray, shape (k,), optional
            True (lagged) rotor speeds, rad/s.
        commands : ndarray, shape (k,), optional
            Commanded rotor speeds, rad/s.
        imu : (ndarray, ndarray), optional
            With ``imu``: the measured gyro (rad/s) and specific force (m/s²), body FLU.
        true_imu : (ndarray, ndarray), optional
            With ``imu`` and a truth: the true gyro and specific force at the IMU.
        """
        assert self._pose is not None, "start() first"
        ref = dict(zip(REFERENCE_COLUMNS, (*reference[0:3], reference[9]), strict=True))
        gyro, accel = imu if imu is not None else (None, None)
        self._pose.write(t, position, quaternion, rotor_speeds, ref, gyro=gyro, accel=accel)
        if self._truth is not None and true_state is not None:
            extra = dict(zip(TRUTH_COLUMNS, (*true_state[VEL], *true_state[RATE]), strict=True))
            extra.update(zip(self._cmd_columns, commands, strict=True))
            gyro, accel = true_imu if true_imu is not None else (None, None)
            self._truth.write(t, true_state[POS], true_state[ATT] / np.linalg.norm(
                true_state[ATT]), true_rotor_speeds, extra, gyro=gyro, accel=accel)

    def finish(self, status: str, summary: dict[str, Any] | None = None) -> None:
        """Close the logs and rewrite the metadata with the final status.

        Parameters
        ----------
        status : str
            Final status (``complete`` or ``aborted``).
        summary : dict, optional
            Keys merged into the metadata.
        """
        for writer in (self._pose, self._truth):
            if writer is not None and not writer.closed:
                writer.close()
        self._meta["status"] = status
        self._meta["samples"] = self._pose.rows_written if self._pose is not None else 0
        if summary:
            self._meta["summary"] = summary
        write_meta(self.directory / "meta.json", self._meta)
