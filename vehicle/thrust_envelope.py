"""The collective thrust a vehicle may command (paper Eq. constraints), defined once.

Stated as thrust acceleration, the collective thrust per mass T/m = ‖a − g‖ (m/s²) that a
flat trajectory's acceleration a implies. Two bounds meet in it:

- the vehicle file's thrust ratios, ``thrust_min_ratio`` g ≤ T/m ≤ ``thrust_max_ratio`` g
  (the planner's thrust constraint);
- the rotors: k rotors between ``rotor_speed_min`` and ``rotor_speed_max`` make a
  collective thrust between k c_T n_min² and k c_T n_max² (`rotor_thrust`, nominal c_T).

The planner decides the ratio bounds exactly and checks every rotor's speed on its own,
which implies the collective rotor bound; the streamer's trajectory check, which has no
rotor speeds, uses the intersection (`ThrustEnvelope.minimum`, `ThrustEnvelope.maximum`).
"""

from __future__ import annotations

from dataclasses import dataclass

from mavsysid.vehicle.config_types import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import rotor_thrust

__all__ = ["ThrustEnvelope", "thrust_envelope"]


@dataclass(frozen=True)
class ThrustEnvelope:
    """Bounds on the thrust acceleration T/m = ‖a − g‖, m/s².

    Attributes
    ----------
    ratio_min, ratio_max : float
        ``thrust_min_ratio`` g and ``thrust_max_ratio`` g.
    rotor_min, rotor_max : float
        k c_T n_min² / m and k c_T n_max² / m: all rotors at their speed limits.
    """

    ratio_min: float
    ratio_max: float
    rotor_min: float
    rotor_max: float

    @property
    def minimum(self) -> float:
        """The least thrust acceleration both bounds allow, m/s²."""
        return max(self.ratio_min, self.rotor_min)

    @property
    def maximum(self) -> float:
        """The greatest thrust acceleration both bounds allow, m/s²."""
        return min(self.ratio_max, self.rotor_max)


def thrust_envelope(config: VehicleConfig) -> ThrustEnvelope:
    """The thrust envelope of a vehicle, from its ``[limits]``, mass, rotors and nominal c_T.

    Parameters
    ----------
    config : VehicleConfig
        Mass (kg), rotor count, nominal c_T (N/(rad/s)²) and `Limits` (thrust ratios,
        rotor speeds in rad/s).

    Returns
    -------
    ThrustEnvelope
        Bounds in m/s².
    """
    lim, k, m = config.limits, config.rotor_count, config.mass
    c_T = config.parameters.c_T
    return ThrustEnvelope(
        ratio_min=lim.thrust_min_ratio * GRAVITY,
        ratio_max=lim.thrust_max_ratio * GRAVITY,
        rotor_min=k * float(rotor_thrust(c_T, lim.rotor_speed_min)) / m,
        rotor_max=k * float(rotor_thrust(c_T, lim.rotor_speed_max)) / m,
    )
