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

    Drawn in call order, or by sample index: the index's block comes from a generator
    seeded with (seed, block), so the noise of a sample does not depend on which other
    samples were asked for (a simulated vehicle measures only at the ticks its telemetry
    and requests need, and those may differ between runs of one flight).

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
        self._seed = seed
        self._rng = np.random.default_rng(seed)
        self._block = -1
        self._noise = config.noise
        self._k = config.rotor_count
        self._enabled = enabled
        self._next = self._BLOCK

    def _draw(self, rng: np.random.Generator) -> None:
        nz, b = self._noise, self._BLOCK
        self._dp = rng.normal(0.0, nz.position_sigma, (b, 3))
        self._dq = quat_exp(rng.normal(0.0, nz.attitude_sigma, (b, 3))).tolist()
        self._dn = rng.normal(0.0, nz.rotor_speed_sigma, (b, self._k))

    def _row(self, sample: int | None) -> int:
        """Row of the drawn block for the next call, or for ``sample``."""
        if sample is None:
            if self._next == self._BLOCK:
                self._draw(self._rng)
                self._block, self._next = -1, 0
            self._next += 1
            return self._next - 1
        block, row = divmod(sample, self._BLOCK)
        if block != self._block:
            self._draw(np.random.default_rng((self._seed, block)))
            self._block, self._next = block, self._BLOCK
        return row

    def apply(
        self, position: np.ndarray, quaternion: np.ndarray, rotor_speeds: np.ndarray,
        sample: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noisy copies of a true pose and rotor speeds (one draw per call, or per index).

        Parameters
        ----------
        position : ndarray, shape (3,)
            m, world ENU.
        quaternion : ndarray, shape (4,)
            Unit [w, x, y, z], body FLU → world ENU.
        rotor_speeds : ndarray, shape (k,)
            rad/s.
        sample : int, optional
            Index of the sample (≥ 0): its noise is the same whatever else was drawn. Do
            not mix with calls in call order on one instance.

        Returns
        -------
        position, quaternion, rotor_speeds : ndarray
            Same shapes and units.
        """
        if not self._enabled:
            return position, quaternion, rotor_speeds
        i = self._row(sample)
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
