"""Model against measurement in forces and torques: what ``estimate --report`` plots.

The *measured* wrench is what the logged motion demands: the pose is put on a uniform
grid (the log's median step), smoothed and differentiated (Savitzky–Golay), then
F = m Rᵀ(a − g) and M = J ω̇ + ω × J ω with the estimated inertia (paper Eq. euler solved
for the torque). The *model* wrench is the paper's rotor model (Eq. drag and the rotor
moments, `mavsysid.vehicle.mav_model.rotor_wrench`) at the logged rotor speeds, the
smoothed states and the estimated θ, smoothed by the same filter so both sides have the
same bandwidth. Model effects are not included: the plot shows what the paper's model
explains. Body frame (FLU), SI.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mavsysid.estimation.flight_data import FlightData
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.constants import GRAVITY
from mavsysid.vehicle.mav_model import rotor_wrench
from mavsysid.vehicle.rotation import (
    continuous_sign,
    quat_conjugate,
    quat_multiply,
    quat_to_matrix,
)
from scipy.signal import savgol_filter

__all__ = ["SMOOTHING_WINDOW", "WrenchComparison", "compare_wrench", "uniform_grid"]

#: Savitzky–Golay window, s: wide enough that motion-capture noise differentiated twice
#: stays well below the rotor forces, short enough to keep manoeuvres (a few Hz).
SMOOTHING_WINDOW = 0.3

_POLYORDER = 3


@dataclass(frozen=True)
class WrenchComparison:
    """Measured and model body wrench over the flight (M grid samples).

    Attributes
    ----------
    t : ndarray, shape (M,)
        s, the log's clock (uniform grid, smoother edges dropped).
    measured_force, model_force : ndarray, shape (M, 3)
        Body force, N.
    measured_torque, model_torque : ndarray, shape (M, 3)
        Body torque, N·m.
    """

    t: np.ndarray
    measured_force: np.ndarray
    model_force: np.ndarray
    measured_torque: np.ndarray
    model_torque: np.ndarray


def uniform_grid(flight: FlightData
                 ) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
    """Grid times, step and position, quaternion, rotor speeds interpolated onto it."""
    t = np.asarray(flight.t, float)
    dt = float(np.median(np.diff(t)))
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)
    q = continuous_sign(flight.quaternion)

    def interp(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        return np.column_stack([np.interp(grid, t, x[:, i]) for i in range(x.shape[1])])

    return grid, dt, interp(flight.position), interp(q), interp(flight.rotor_speeds)


def _window(dt: float, samples: int) -> int:
    """Odd smoother length for step ``dt``, at most the number of samples."""
    n = max(_POLYORDER + 2, round(SMOOTHING_WINDOW / dt))
    n += 1 - n % 2
    return min(n, samples - 1 + samples % 2)


def compare_wrench(flight: FlightData, config: VehicleConfig, theta: np.ndarray
                   ) -> WrenchComparison:
    """Measured and model body force and torque along a flight (module docstring).

    Parameters
    ----------
    flight : FlightData
        Pose and rotor speeds (any sampling; put on a uniform grid here).
    config : VehicleConfig
        Mass and rotor geometry.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI (usually the final estimate).

    Returns
    -------
    WrenchComparison
        Empty arrays when the flight is too short for the smoother.
    """
    theta = np.asarray(theta, float)
    t, dt, p, q, n = uniform_grid(flight)
    win = _window(dt, len(t))
    if win < _POLYORDER + 2:
        empty = np.empty((0, 3))
        return WrenchComparison(np.empty(0), empty, empty, empty, empty)

    def smooth(x: np.ndarray, deriv: int = 0) -> np.ndarray:
        return savgol_filter(x, win, _POLYORDER, deriv=deriv, delta=dt, axis=0)

    q_s = smooth(q)
    q_s /= np.linalg.norm(q_s, axis=1, keepdims=True)
    rot_t = np.swapaxes(quat_to_matrix(q_s), -1, -2)
    # q̇ = ½ q ⊗ [0, ω]  ⇒  [0, ω] = 2 q̄ ⊗ q̇ (body rates).
    w = 2.0 * quat_multiply(quat_conjugate(q_s), smooth(q, 1))[:, 1:]
    w_dot = smooth(w, 1)
    v_b = np.einsum("nij,nj->ni", rot_t, smooth(p, 1))
    specific = np.einsum("nij,nj->ni", rot_t, smooth(p, 2) + np.array([0.0, 0.0, GRAVITY]))
    inertia = theta[3:6]
    measured_torque = inertia * w_dot + np.cross(w, inertia * w)
    force, torque = rotor_wrench(n, theta, config.rotor_positions, config.rotor_directions,
                                 v_b, w)
    keep = slice(win // 2, len(t) - win // 2)
    return WrenchComparison(t[keep], config.mass * specific[keep], smooth(force)[keep],
                            measured_torque[keep], smooth(torque)[keep])
