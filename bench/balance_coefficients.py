"""The force and torque balance's coefficients on flights, beside those a vehicle file implies.

θ reaches the balance only through its coefficients (`TORQUE_COEFFICIENTS`,
`FORCE_COEFFICIENTS` of `mavsysid.estimation.balance.rows`): c_T/j_x, c_M/j_z, the
gyroscopic g_x = −(j_z − j_y)/j_x, g_y = −(j_x − j_z)/j_y, the yaw drag c_T c_D/j_z, ….
Per flight this prints each coefficient the flight fits (the balance's regression at its
chosen band and offset, before θ is formed) beside the value the vehicle file's θ implies
(`coefficients_from_theta`); their regression σ (unwidened, and not on a common scale
for every column) is left out. A coefficient far from the file's value points at the law
the simulator or vehicle has otherwise: on ArduCopter SITL, whose physics leaves out
ω × Jω (docs/vehicles/sitl_quad.md), g_x and g_y come out near 0 where the reference J
implies ∓1, and j_z, which the balance forms from them, has no route to its value.

    python bench/balance_coefficients.py LOG [LOG ...] --vehicle sitl_quad
"""

from __future__ import annotations

import argparse

import numpy as np
from mavsysid.estimation.answer import with_imu_quantities
from mavsysid.estimation.balance.fit import balance_coefficients
from mavsysid.estimation.balance.rows import STACKED_COEFFICIENTS
from mavsysid.estimation.balance.theta import coefficients_from_theta
from mavsysid.estimation.readers import load_flight
from mavsysid.estimation.results import prior_from_config
from mavsysid.vehicle.config import load_vehicle


def coefficient_table(log: str, vehicle: str) -> list[tuple[str, float, float]]:
    """Per fitted coefficient: name, value and the value the vehicle file's θ implies."""
    config = load_vehicle(vehicle)
    flight = load_flight(log, config)
    config = with_imu_quantities(config, flight)
    prior = prior_from_config(config)
    value = balance_coefficients(flight, config, prior)
    implied = coefficients_from_theta(np.concatenate([config.theta,
                                                      prior.value[len(config.theta):]]))
    return [(name, float(value[i]), float(implied[i]))
            for i, name in enumerate(STACKED_COEFFICIENTS)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    parser.add_argument("--vehicle", required=True)
    args = parser.parse_args()
    for log in args.logs:
        print(log)
        print(f"  {'coefficient':16s} {'fitted':>11s} {'file implies':>12s}")
        for name, value, implied in coefficient_table(log, args.vehicle):
            print(f"  {name:16s} {value:11.4g} {implied:12.4g}")


if __name__ == "__main__":
    main()
