"""A simulated IMU: the ideal gyro and specific force at the IMU, with white noise and biases.

Shared by the offline simulator (`mavsysid.flight.offline.simulator`) and the simulated
MAVLink vehicle (`mavsysid.flight.simvehicle.physics`). The ideal reading is the model's
(`mavsysid.vehicle.imu.imu_kernel`: ω, and F_B/m plus the lever-arm terms at the IMU's
position); the sensor adds, per axis, a constant bias drawn once per flight (σ
``[noise] gyro_bias_sigma``, ``accel_bias_sigma``) and white noise on every sample (σ
``gyro_sigma``, ``accel_sigma``). Everything is in body FLU.

The noise of a sample is drawn by its index, from a generator seeded with (seed, the
IMU's stream, block), like `mavsysid.flight.offline.sensor_noise.SensorNoise`'s: it does
not depend on which other samples were measured, and it never draws from the pose
noise's generators, so adding the IMU leaves a flight's pose noise as it was.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.imu import imu_kernel
from mavsysid.vehicle.rotation import quat_to_matrix

__all__ = ["ImuSensor"]

_ZERO = np.zeros(3)
#: Keys of the IMU's generators beside the seed: not any other sensor's.
_BIAS_STREAM, _NOISE_STREAM = 0x1B1A5, 0x1A015E


class ImuSensor:
    """The simulated IMU of one flight: its position, biases and noise.

    Parameters
    ----------
    config : VehicleConfig
        Its ``[noise]`` σ of the IMU, its geometry and mass (for the ideal reading).
    seed : int
        Seed of the biases and the noise.
    enabled : bool
        False: no bias and no noise (`measure` returns the ideal reading).
    position : sequence of 3 float, optional
        The IMU's true offset from the centre of gravity, m, body FLU; default the
        config's ``[imu] position``, else the centre of gravity.
    """

    _BLOCK = 1000

    def __init__(self, config: VehicleConfig, seed: int, enabled: bool,
                 position: Sequence[float] | None = None) -> None:
        noise = config.noise
        self.config = config
        self.enabled = enabled
        default = config.imu_position if config.imu_position is not None else (0.0, 0.0, 0.0)
        self.position = np.array(default if position is None else position, dtype=float)
        rng = np.random.default_rng((seed, _BIAS_STREAM))
        gyro_bias, accel_bias = (rng.normal(0.0, sigma, 3) for sigma in (
            noise.gyro_bias_sigma, noise.accel_bias_sigma))
        self.gyro_bias = gyro_bias if enabled else np.zeros(3)
        self.accel_bias = accel_bias if enabled else np.zeros(3)
        self._sigma = np.repeat([noise.gyro_sigma, noise.accel_sigma], 3)
        self._r = np.ascontiguousarray(config.rotor_positions)
        self._eps = np.ascontiguousarray(config.rotor_directions)
        self._seed = seed
        self._block = -1
        self._noise = np.zeros((self._BLOCK, 6))

    def ideal(self, x: np.ndarray, n: np.ndarray, theta: np.ndarray,
              force_ext: np.ndarray | None = None, torque_ext: np.ndarray | None = None,
              landed: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The true gyro (rad/s) and specific force (m/s²) at the IMU, body FLU.

        Parameters
        ----------
        x : ndarray, shape (13,)
            True state [p, v_B, q, ω].
        n : ndarray, shape (k,)
            Actual rotor speeds, rad/s.
        theta : ndarray, shape (6,)
            The truth's θ.
        force_ext, torque_ext : ndarray, shape (3,), optional
            Extra body force (N) and torque (N·m) acting now.
        landed : bool
            Resting on the ground: the ground carries the weight, so the reading is the
            reaction, +g along the world's up axis seen in the body, and no rotation.
        """
        if landed:
            up = quat_to_matrix(np.asarray(x[6:10], dtype=float))[2]  # Rᵀ e_z
            return np.zeros(3), GRAVITY * up
        out = np.empty(6)
        imu_kernel(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(n, dtype=float),
                   np.ascontiguousarray(theta, dtype=float), float(self.config.mass), self._r,
                   self._eps, _ZERO if force_ext is None else force_ext,
                   _ZERO if torque_ext is None else torque_ext, self.position, out)
        return out[:3], out[3:]

    def _row(self, sample: int) -> np.ndarray:
        block, row = divmod(sample, self._BLOCK)
        if block != self._block:
            rng = np.random.default_rng((self._seed, _NOISE_STREAM, block))
            self._noise = rng.normal(size=(self._BLOCK, 6)) * self._sigma
            self._block = block
        return self._noise[row]

    def measure(self, gyro: np.ndarray, accel: np.ndarray,
                sample: int) -> tuple[np.ndarray, np.ndarray]:
        """The IMU's reading of the true ``gyro`` and ``accel`` at sample index ``sample``.

        Parameters
        ----------
        gyro : ndarray, shape (3,)
            True body rates, rad/s, FLU.
        accel : ndarray, shape (3,)
            True specific force at the IMU, m/s², FLU.
        sample : int
            The sample's index (≥ 0): its noise is the same whatever else was measured.

        Returns
        -------
        gyro, accel : ndarray, shape (3,)
            With the biases and that sample's noise (unchanged when disabled).
        """
        if not self.enabled:
            return np.asarray(gyro, dtype=float), np.asarray(accel, dtype=float)
        noise = self._row(sample)
        return gyro + self.gyro_bias + noise[:3], accel + self.accel_bias + noise[3:]

    def truth(self) -> dict[str, list[float]]:
        """The IMU's truth for a flight's metadata: position (m), biases (rad/s, m/s²),
        noise σ per sample, all body FLU."""
        noise = self.config.noise
        on = 1.0 if self.enabled else 0.0
        return {"position_m": self.position.tolist(),
                "gyro_bias_rad_s": self.gyro_bias.tolist(),
                "accel_bias_m_s2": self.accel_bias.tolist(),
                "gyro_sigma_rad_s": [on * noise.gyro_sigma] * 3,
                "accel_sigma_m_s2": [on * noise.accel_sigma] * 3}
