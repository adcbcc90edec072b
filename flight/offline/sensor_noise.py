"""Motion-capture and rotor-speed noise on what a simulated flight reports.

Shared by the offline simulator (`mavsysid.flight.offline.simulator`) and the simulated
MAVLink vehicle (`mavsysid.flight.simvehicle.physics`); σ values come from the vehicle
config's ``[noise]`` table.
"""

from __future__ import annotations

import numpy as np
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.rotation import quat_exp

__all__ = ["SensorNoise"]


class SensorNoise:
    """Motion-capture and rotor-speed noise, drawn in vectorised blocks from one seed.

    Position gets N(0, σ_p² I), attitude q ⊗ Exp(φ) with φ ~ N(0, σ_φ² I) (body frame),
    rotor speeds N(0, σ_n² I).

    Parameters
    ----------
    config : VehicleConfig
        σ_p (m), σ_φ (rad) and σ_n (rad/s) from ``config.noise``; its rotor count k.
    seed : int
        Seed of the generator.
    enabled : bool
        False: `apply` returns its inputs unchanged (and draws nothing).
    """

    _BLOCK = 1000

    def __init__(self, config: VehicleConfig, seed: int, enabled: bool) -> None:
        self._rng = np.random.default_rng(seed)
        self._noise = config.noise
        self._k = config.rotor_count
        self._enabled = enabled
        self._next = self._BLOCK

    def _draw(self) -> None:
        nz, b = self._noise, self._BLOCK
        self._dp = self._rng.normal(0.0, nz.position_sigma, (b, 3))
        self._dq = quat_exp(self._rng.normal(0.0, nz.attitude_sigma, (b, 3))).tolist()
        self._dn = self._rng.normal(0.0, nz.rotor_speed_sigma, (b, self._k))
        self._next = 0

    def apply(
        self, position: np.ndarray, quaternion: np.ndarray, rotor_speeds: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noisy copies of a true pose and rotor speeds (one draw per call).

        Parameters
        ----------
        position : ndarray, shape (3,)
            m, world ENU.
        quaternion : ndarray, shape (4,)
            Unit [w, x, y, z], body FLU → world ENU.
        rotor_speeds : ndarray, shape (k,)
            rad/s.

        Returns
        -------
        position, quaternion, rotor_speeds : ndarray
            Same shapes and units.
        """
        if not self._enabled:
            return position, quaternion, rotor_speeds
        if self._next == self._BLOCK:
            self._draw()
        i = self._next
        self._next += 1
        # One Hamilton product on plain floats: numpy's per-call overhead would dominate.
        aw, ax, ay, az = quaternion.tolist()
        bw, bx, by, bz = self._dq[i]
        q = np.array([
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ])
        return position + self._dp[i], q, rotor_speeds + self._dn[i]
