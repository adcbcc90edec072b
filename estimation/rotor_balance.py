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

`rescale_wrong_rotor` corrects the one case the data can: a single rotor channel reading a
constant share of its speed (the Crazyflie brushed flights' rotor 1, whose RPM deck reads
half while its motor command matches the others'). The scale s of the rotor whose median
speed is furthest below the others' is the one that puts the centroid at the centre in the
least-squares sense over the flying samples: with a_k = r_w n_w,k² and b_k = Σ_i r_i n_i,k²
(hubs relative to the centre), s² − 1 = −Σ a_k·b_k / Σ a_k·a_k. The flight is corrected only
when that brings the centroid within `MAX_CENTROID_OFFSET`, and the correction is said in a
note; otherwise the rotor speeds contradict each other and the flight is refused.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.vehicle.config import VehicleConfig

from mavsysid.errors import JobFailedError

__all__ = ["MAX_CENTROID_OFFSET", "check_rotor_balance", "rescale_wrong_rotor",
           "thrust_centroid_offset"]

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


def rescale_wrong_rotor(flight: FlightData, config: VehicleConfig,
                        max_offset: float = MAX_CENTROID_OFFSET
                        ) -> tuple[FlightData, str | None]:
    """The flight with one rotor channel rescaled when it alone puts the centroid off centre.

    Parameters
    ----------
    flight : FlightData
    config : VehicleConfig
        Rotor positions.
    max_offset : float
        Share of the arm.

    Returns
    -------
    flight : FlightData
        Unchanged when the centroid is within ``max_offset`` or no single-rotor scale brings
        it there (then `check_rotor_balance` refuses it); else with the rotor's speeds
        multiplied by s.
    note : str or None
        What was corrected, and why.
    """
    offset = thrust_centroid_offset(flight.rotor_speeds, config)
    if float(np.hypot(*offset)) <= max_offset:
        return flight, None
    n = np.asarray(flight.rotor_speeds, float)
    median = np.median(n, axis=0)
    if not np.median(median) > 0.0:
        return flight, None
    worst = int(np.argmin(median / np.median(median)))
    r = config.rotor_positions[:, :2]
    r = r - r.mean(axis=0)
    n2 = n**2
    use = (n2.sum(axis=1) > 0.0) & (n[:, worst] > 0.0)
    a = n2[use, worst, None] * r[worst]
    b = n2[use] @ r
    denominator = float(np.sum(a * a))
    if not denominator > 0.0:
        return flight, None
    scale_sq = 1.0 - float(np.sum(a * b)) / denominator
    if not scale_sq > 0.0:
        return flight, None
    scale = float(np.sqrt(scale_sq))
    corrected = n.copy()
    corrected[:, worst] *= scale
    if float(np.hypot(*thrust_centroid_offset(corrected, config))) > max_offset:
        return flight, None
    note = (f"{flight.source}: rotor {worst + 1}'s speeds put the thrust centroid "
            f"{100 * float(np.hypot(*offset)):.0f} % of the arm off the rotors' centre while "
            f"the vehicle holds its attitude; its channel reads {100 / scale:.0f} % of the "
            f"speed that balances the others and was multiplied by {scale:.3g} (a rotor-speed "
            "channel reading a constant share; check its sensor)")
    return dataclasses.replace(flight, rotor_speeds=corrected,
                               warnings=(*flight.warnings, note)), note
