"""One step of the simulated truth: RK4 on the model's dynamics with motor lag, plus effects.

Shared by the offline simulator (`mavsysid.flight.offline.simulator`) and the simulated
MAVLink vehicle (`mavsysid.flight.simvehicle.physics`), so that both fly the same physics.
The truth state is ``y = [x (13), n (k)]``: the model state [p, v_B, q, ω] and the actual
(lagged) rotor speeds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from mavsysid.flight.offline.effects import TruthEffect
from mavsysid.vehicle.dynamics import STATE_DIM, derivative_kernel

__all__ = ["advance_truth", "summed_effect_wrench"]


@numba.njit(cache=True)
def advance_truth(y, n_cmd, dt, steps, tau, theta, mass, r, eps, force, torque):
    """Advance the truth state by ``steps`` RK4 steps, in place. Compiled (numba).

    The rotor speeds follow their commands with a first-order lag,
    ṅ = (n_cmd - n) / τ; with τ ≤ 0 they equal the commands at once.

    Parameters
    ----------
    y : ndarray, shape (13 + k,)
        Truth state [x, n] (m, m/s, unit quaternion, rad/s; rotor speeds rad/s); updated,
        its quaternion renormalised after each step.
    n_cmd : ndarray, shape (k,)
        Commanded rotor speeds, rad/s, held over the steps.
    dt : float
        Step, s.
    steps : int
        Number of steps (0 only loads the compiled kernel).
    tau : float
        Motor time constant, s.
    theta : ndarray, shape (6,)
        The truth's θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI.
    mass : float
        kg.
    r : ndarray, shape (k, 3)
        Rotor positions, m, body frame.
    eps : ndarray, shape (k,)
        Rotor directions, ±1.
    force, torque : ndarray, shape (3,)
        Extra body force (N) and torque (N·m) of truth-side effects, held over the steps.
    """
    nx = 13
    dim = y.shape[0]
    k1 = np.empty(dim)
    k2 = np.empty(dim)
    k3 = np.empty(dim)
    k4 = np.empty(dim)
    tmp = np.empty(dim)
    if tau <= 0.0:
        y[nx:] = n_cmd
    for _ in range(steps):
        for stage in range(4):
            if stage == 0:
                tmp[:] = y
                kk = k1
            elif stage == 1:
                tmp[:] = y + 0.5 * dt * k1
                kk = k2
            elif stage == 2:
                tmp[:] = y + 0.5 * dt * k2
                kk = k3
            else:
                tmp[:] = y + dt * k3
                kk = k4
            derivative_kernel(tmp[:nx], tmp[nx:], theta, mass, r, eps, force, torque, kk[:nx])
            if tau > 0.0:
                kk[nx:] = (n_cmd - tmp[nx:]) / tau
            else:
                kk[nx:] = 0.0
        y += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        q = y[6:10]
        y[6:10] = q / np.sqrt(np.sum(q * q))


def summed_effect_wrench(
    effects: Sequence[TruthEffect], t: float, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Summed extra body force and torque of truth-side effects at one instant.

    Parameters
    ----------
    effects : sequence of TruthEffect
        The effects whose `TruthEffect.wrench` to add (None from one adds nothing).
    t : float
        Time since the flight start, s.
    y : ndarray, shape (13 + k,)
        Truth state [x, n].

    Returns
    -------
    force, torque : ndarray, shape (3,)
        N and N·m, body frame.
    """
    force = np.zeros(3)
    torque = np.zeros(3)
    for effect in effects:
        w = effect.wrench(t, y[:STATE_DIM], y[STATE_DIM:])
        if w is not None:
            force += w[0]
            torque += w[1]
    return force, torque
