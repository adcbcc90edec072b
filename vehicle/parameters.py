"""The estimated quantities: θ of the paper and nuisance terms, each defined once by name.

An `EstimatedQuantity` says what it is (name, unit), what is known of it before the flight
(its physical bounds, its prior value and σ) and where it enters the model (its `term`).
The paper's six, `PAPER_THETA` = [c_T, c_D, c_M, j_x, j_y, j_z], enter through the rotor
law and Euler's equation (`mavsysid.vehicle.mav_model`, compiled into the dynamics and
their Jacobians); their prior value is the vehicle file's. Any other quantity is a
*nuisance*: it enters through its `QuantityTerm`, an extra body force and torque linear in
its value (a thrust-curve exponent, a thrust drift, an unmodelled force), and is estimated
beside θ by the filter (`mavsysid.vehicle.linearization.ErrorStateModel` carries its error
state), the batch refinement and the force and torque balance, and answered and reported
by name. D-optimality (paper Eq. dopt) stays over the paper's six.

A new nuisance quantity is one `EstimatedQuantity` with its `QuantityTerm`, handed to the
estimator (`mavsysid.estimation.EstimatorSettings.extra_quantities`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from mavsysid.vehicle.effect_base import EffectInputs

__all__ = [
    "C_D",
    "C_M",
    "C_T",
    "INERTIA",
    "MAX_RELATIVE_SIGMA",
    "PAPER_THETA",
    "PARAMETER_NAMES",
    "PARAMETER_UNITS",
    "EstimatedQuantity",
    "QuantityTerm",
    "quantity_names",
]

#: Largest σ / |θ| of a parameter of θ a flight determines: its 95 % interval about ±25 %,
#: a fourfold narrowing of the tool's default prior. The estimate's answer
#: (`mavsysid.estimation.results.parameter_status`) and the plan's expectation both use it.
MAX_RELATIVE_SIGMA = 0.125


class QuantityTerm:
    """Where a nuisance quantity enters the model, linear in its value.

    On the vehicle (``channel`` "wrench"): a body force and torque the model adds to the
    paper's F_B and M_B (paper Eqs. newton, euler), ``value × wrench_basis``. In a sensor
    (``channel`` "gyro" or "accel"): what the IMU reads beyond the vehicle's motion,
    ``value × reading_basis`` (a bias, the IMU's offset from the centre of gravity); the
    dynamics do not see it. A term that is not linear in its quantity is written as its
    first-order expansion about the prior value.
    """

    #: Where the quantity enters: "wrench", "gyro" or "accel".
    channel: ClassVar[str] = "wrench"

    def wrench_basis(self, inputs: EffectInputs) -> tuple[np.ndarray, np.ndarray]:
        """Body force (N) and torque (N·m) per unit of the quantity, each shape (N, 3).

        Parameters
        ----------
        inputs : EffectInputs
            The states, rotor speeds and θ along the flight.
        """
        zero = np.zeros((inputs.t.shape[0], 3))
        return zero, zero

    def reading_basis(self, inputs: EffectInputs) -> np.ndarray:
        """What the IMU channel reads per unit of the quantity, shape (N, 3), body frame.

        Parameters
        ----------
        inputs : EffectInputs
            The states (with ``angular_acceleration`` where the reading needs it).
        """
        return np.zeros((inputs.t.shape[0], 3))


@dataclass(frozen=True)
class EstimatedQuantity:
    """One quantity the estimator answers.

    Attributes
    ----------
    name : str
        Identifier in the answer, its JSON and report.
    unit : str
    description : str
    lower, upper : float
        Physical bounds, SI (a value outside them is not physical).
    nominal : float
        Prior value of a nuisance quantity, SI (the paper's six take the vehicle file's).
    prior_sigma : float
        Prior σ of a nuisance quantity, SI; NaN for the paper's six, whose σ is relative to
        the vehicle file's value.
    tolerance : float
        Relative accuracy asked of the estimate: two estimates closer than this fraction of
        the value agree whatever their σ.
    term : QuantityTerm or None
        Where a nuisance quantity enters the model; None for the paper's six.
    """

    name: str
    unit: str
    description: str
    lower: float = -math.inf
    upper: float = math.inf
    nominal: float = 0.0
    prior_sigma: float = math.nan
    tolerance: float = 0.05
    term: QuantityTerm | None = None

    @property
    def paper(self) -> bool:
        """One of the paper's six (entering through the rotor law and Euler's equation)."""
        return self.term is None


#: The paper's θ, in the order of every θ array in mavsysid (paper Section "MAV Model").
PAPER_THETA: tuple[EstimatedQuantity, ...] = (
    EstimatedQuantity("c_T", "N/(rad/s)²", "thrust coefficient: rotor thrust c_T n²",
                      lower=0.0),
    EstimatedQuantity("c_D", "s/m", "rotor drag coefficient: −c_T n² diag(c_D, c_D, 0)"
                      "(v_B + ω × r_i)", lower=0.0, tolerance=0.15),
    EstimatedQuantity("c_M", "N·m/(rad/s)²", "moment coefficient: rotor moment c_M n²",
                      lower=0.0),
    EstimatedQuantity("j_x", "kg·m²", "moment of inertia about x_B", lower=0.0),
    EstimatedQuantity("j_y", "kg·m²", "moment of inertia about y_B", lower=0.0),
    EstimatedQuantity("j_z", "kg·m²", "moment of inertia about z_B", lower=0.0),
)

#: Names of θ in order.
PARAMETER_NAMES: tuple[str, ...] = tuple(q.name for q in PAPER_THETA)

#: Unit of each parameter of θ, by name (messages, tables and the estimate JSON).
PARAMETER_UNITS: dict[str, str] = {q.name: q.unit for q in PAPER_THETA}

#: Where θ's entries sit in every θ array (the nuisance quantities follow the six).
C_T, C_D, C_M = (PARAMETER_NAMES.index(n) for n in ("c_T", "c_D", "c_M"))
INERTIA = slice(PARAMETER_NAMES.index("j_x"), PARAMETER_NAMES.index("j_z") + 1)


def quantity_names(extras: tuple[EstimatedQuantity, ...] = ()) -> tuple[str, ...]:
    """The names of θ followed by those of the nuisance quantities.

    Parameters
    ----------
    extras : tuple of EstimatedQuantity
        The nuisance quantities, in their order after θ.
    """
    return PARAMETER_NAMES + tuple(q.name for q in extras)
