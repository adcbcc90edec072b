"""Rotor speeds that contradict a vehicle holding its attitude: a rotor channel reading wrong.

A multirotor that holds its attitude balances its rotors' thrust about the centre of
gravity: the thrust-weighted centroid of the rotor hubs, Σ r_i n_i² / Σ n_i², lies at the
centre of gravity (the rotor drag's and yaw moments aside). A balanced vehicle keeps it
within a few per cent of the arm from the rotors' centre (the Crazyflie flights of
docs/estimation-real-flights.md: 1–5 %). A rotor-speed channel that reads half the true
speed, or drops to zero, moves it by a third of the arm or more, while the vehicle keeps
flying level. Then every balance that uses the rotor speeds is wrong (c_T by tens of per
cent), and the honest answer is that the data contradict each other.

`check_rotor_balance` refuses a flight whose median centroid lies more than
`MAX_CENTROID_OFFSET` of the arm off the rotors' centre (4× what balanced vehicles show, and
below what one rotor reading half its speed gives on a quadrotor, about 0.3).
"""

from __future__ import annotations

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import JobFailedError

__all__ = ["MAX_CENTROID_OFFSET", "check_rotor_balance", "thrust_centroid_offset"]

#: Largest offset of the thrust centroid from the rotors' centre, as a share of the arm.
MAX_CENTROID_OFFSET = 0.2


def thrust_centroid_offset(rotor_speeds: np.ndarray, config: VehicleConfig) -> np.ndarray:
    """Median thrust-weighted hub centroid relative to the rotors' centre, in arms, (2,).

    Parameters
    ----------
    rotor_speeds : ndarray, shape (N, k)
        rad/s.
    config : VehicleConfig
        Rotor positions.
    """
    r = config.rotor_positions[:, :2]
    centre = r.mean(axis=0)
    arm = float(np.mean(np.linalg.norm(r - centre, axis=1)))
    n2 = np.asarray(rotor_speeds, float) ** 2
    total = n2.sum(axis=1)
    flying = total > 0.0
    centroid = (n2[flying] @ (r - centre)) / total[flying, None]
    return np.median(centroid, axis=0) / arm if flying.any() else np.zeros(2)


def check_rotor_balance(flight: FlightData, config: VehicleConfig,
                        max_offset: float = MAX_CENTROID_OFFSET) -> None:
    """Refuse, in one line, rotor speeds that put the thrust centroid far off centre.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
    max_offset : float
        Share of the arm.

    Raises
    ------
    JobFailedError
        Naming the offset and the rotor whose median speed is furthest below the others'.
    """
    offset = thrust_centroid_offset(flight.rotor_speeds, config)
    size = float(np.hypot(*offset))
    if size <= max_offset:
        return
    median = np.median(flight.rotor_speeds, axis=0)
    ratio = median / np.median(median)
    worst = int(np.argmin(ratio))
    raise JobFailedError(
        f"{flight.source}: the rotor speeds put the thrust centroid {100 * size:.0f} % of the "
        f"arm off the rotors' centre while the vehicle holds its attitude (at most "
        f"{100 * max_offset:.0f} % expected); rotor {worst + 1}'s median speed is "
        f"{100 * ratio[worst]:.0f} % of the rotors' median: a rotor-speed channel reading "
        "wrong, or a centre of gravity far off the rotors' centre")
