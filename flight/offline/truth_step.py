"""One step of the simulated truth: RK4 on the model's dynamics with motor lag, plus effects.

Shared by the offline simulator (`mavsysid.flight.offline.simulator`) and the simulated
MAVLink vehicle (`mavsysid.flight.simvehicle.physics`), so that both fly the same physics.
The truth state is ``y = [x (13), n (k)]``: the model state [p, v_B, q, ω] and the actual
(lagged) rotor speeds.

The rotor speeds follow their commands with a first-order lag, ṅ = (n_cmd − n) / τ,
which does not depend on the rigid-body state. One RK4 step of the whole of ``y`` is
therefore the lag's RK4 stages (`_lag_stages`) handed to the model's one integrator,
`mavsysid.vehicle.dynamics.rk4_step_kernel`, which the estimator integrates with too.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from mavsysid.flight.offline.effects import TruthEffect
from mavsysid.vehicle.dynamics import STATE_DIM, rk4_step_kernel

__all__ = ["advance_truth", "summed_effect_wrench"]


@numba.njit(cache=True)
def _lag_stages(n, n_cmd, tau, dt, n_stages, n_end):
    """The lagged rotor speeds at the RK4 stages of one step, and at its end.

    RK4 of ṅ = (n_cmd − n) / τ with ``n_cmd`` held: ``n_stages`` (4, k) receives the
    speeds each stage evaluates the model at, ``n_end`` (k,) the speeds after the step.
    """
    for i in range(n.shape[0]):
        d1 = (n_cmd[i] - n[i]) / tau
        n_stages[0, i] = n[i]
        n_stages[1, i] = n[i] + 0.5 * dt * d1
        d2 = (n_cmd[i] - n_stages[1, i]) / tau
        n_stages[2, i] = n[i] + 0.5 * dt * d2
        d3 = (n_cmd[i] - n_stages[2, i]) / tau
        n_stages[3, i] = n[i] + dt * d3
        d4 = (n_cmd[i] - n_stages[3, i]) / tau
        n_end[i] = n[i] + dt / 6.0 * (d1 + 2.0 * d2 + 2.0 * d3 + d4)


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
    n_stages = np.empty((4, n_cmd.shape[0]))
    n_end = np.empty(n_cmd.shape[0])
    w_stages = np.empty((4, 6))
    for stage in range(4):
        w_stages[stage, 0:3] = force
        w_stages[stage, 3:6] = torque
    state = np.empty(STATE_DIM)
    if tau <= 0.0:
        y[STATE_DIM:] = n_cmd
        for stage in range(4):
            n_stages[stage] = n_cmd
    for _ in range(steps):
        if tau > 0.0:
            _lag_stages(y[STATE_DIM:], n_cmd, tau, dt, n_stages, n_end)
        rk4_step_kernel(y[:STATE_DIM], n_stages, w_stages, theta, dt, mass, r, eps, state)
        y[:STATE_DIM] = state
        if tau > 0.0:
            y[STATE_DIM:] = n_end


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
