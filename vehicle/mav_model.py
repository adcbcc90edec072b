"""The laws of the paper's Section "MAV Model", each written once.

The rotor wrench (paper Eqs. drag, newton, euler: thrust c_T n_i², rotor drag and the
yaw moment −ε_i c_M n_i²) and Euler's equation ω̇ = J⁻¹(M − ω × J ω) are stated here
and nowhere else. The dynamics (`mavsysid.vehicle.dynamics`), the linearisation's
nominal (`mavsysid.vehicle.linearization`), the model effects and the residual model
(`mavsysid.discrepancy.residuals`) all call these functions, so they cannot disagree.

Each law comes as a numba kernel for one sample (called from compiled code, such as
the simulator's 1 kHz integrator and the EKF) and as a vectorised function over
arrays of samples built on that same kernel. Conventions are those of
docs/architecture.md: body frame FLU, θ = [c_T, c_D, c_M, j_x, j_y, j_z] in SI units,
rotor speeds n in rad/s, rotor positions r_i relative to the centre of gravity (m),
spin directions ε_i = ±1.

This module depends on numpy and numba only, so every other module of the model can
import it.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "add_rotor_wrench",
    "collective_thrust",
    "euler_acceleration",
    "euler_kernel",
    "rotor_speed_for_thrust",
    "rotor_thrust",
    "rotor_thrust_kernel",
    "rotor_wrench",
]


def rotor_thrust(c_T: float, n: np.ndarray | float) -> np.ndarray | float:
    """Thrust of each rotor T_i = c_T n_i² along z_B (paper: rotor thrust), N.

    Parameters
    ----------
    c_T : float
        Thrust coefficient, N/(rad/s)².
    n : float or ndarray, any shape
        Rotor speeds, rad/s.

    Returns
    -------
    float or ndarray, shape of ``n``
        Thrust per rotor, N.
    """
    return c_T * (n * n)


#: `rotor_thrust` compiled by numba, for the kernels (the same source, not a copy).
rotor_thrust_kernel = numba.njit(cache=True)(rotor_thrust)


def collective_thrust(c_T: float, n: np.ndarray) -> np.ndarray:
    """Σ_i c_T n_i², the summed thrust of all rotors (rotor drag not included), N.

    Parameters
    ----------
    c_T : float
        Thrust coefficient, N/(rad/s)².
    n : ndarray, shape (..., k)
        Rotor speeds, rad/s.

    Returns
    -------
    ndarray, shape (...)
        Collective thrust, N.
    """
    return np.sum(rotor_thrust(c_T, np.asarray(n, dtype=float)), axis=-1)


def rotor_speed_for_thrust(c_T: float, thrust: np.ndarray | float) -> np.ndarray | float:
    """The rotor speed n = √(T / c_T) at which one rotor makes ``thrust`` (N), rad/s.

    Parameters
    ----------
    c_T : float
        Thrust coefficient, N/(rad/s)².
    thrust : float or ndarray
        Thrust of one rotor, N.
    """
    return np.sqrt(thrust / c_T)


@numba.njit(cache=True)
def add_rotor_wrench(n, theta, r, eps, v, w, force, torque):
    """Add the rotors' body force Σ F_i and torque Σ (M_i + r_i × F_i) into ``force``/``torque``.

    Per rotor (paper Eq. drag and the rotor moment), with T_i = c_T n_i² and hub
    velocity h_i = v_B + ω × r_i:

        F_i = T_i e_z − T_i diag(c_D, c_D, 0) h_i,      M_i = −ε_i c_M n_i² e_z.

    The sums are the rotor terms of paper Eqs. newton and euler. Adding into the given
    arrays lets a caller start from an external wrench (F_ext, M_ext) without changing
    the order of the floating-point sums.

    Parameters
    ----------
    n : ndarray, shape (k,)
        Rotor speeds, rad/s.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z]; only the first three are read.
    r : ndarray, shape (k, 3)
        Rotor positions, m, body frame.
    eps : ndarray, shape (k,)
        Spin directions ε_i, ±1.
    v, w : ndarray, shape (3,)
        Body velocity v_B (m/s) and body rates ω (rad/s).
    force, torque : ndarray, shape (3,)
        Accumulators, N and N·m; updated in place.
    """
    c_T, c_D, c_M = theta[0], theta[1], theta[2]
    vx, vy = v[0], v[1]
    wx, wy, wz = w[0], w[1], w[2]
    fx, fy, fz = force[0], force[1], force[2]
    mx, my, mz = torque[0], torque[1], torque[2]
    for i in range(n.shape[0]):
        n2 = n[i] * n[i]
        thrust = rotor_thrust_kernel(c_T, n[i])
        rx, ry, rz = r[i, 0], r[i, 1], r[i, 2]
        # Paper Eq. drag: hub velocity v_B + ω × r_i, only its xy part is opposed.
        hx = vx + wy * rz - wz * ry
        hy = vy + wz * rx - wx * rz
        fix = -thrust * c_D * hx
        fiy = -thrust * c_D * hy
        fiz = thrust
        fx += fix
        fy += fiy
        fz += fiz
        mx += ry * fiz - rz * fiy
        my += rz * fix - rx * fiz
        mz += rx * fiy - ry * fix - eps[i] * c_M * n2
    force[0], force[1], force[2] = fx, fy, fz
    torque[0], torque[1], torque[2] = mx, my, mz


@numba.njit(cache=True)
def euler_kernel(torque, w, J, out):
    """Paper Eq. euler, ω̇ = J⁻¹ (M_B − ω × J ω) with J = diag(j_x, j_y, j_z), into ``out``.

    Parameters
    ----------
    torque : ndarray, shape (3,)
        Body torque M_B, N·m.
    w : ndarray, shape (3,)
        Body rates ω, rad/s.
    J : ndarray, shape (3,)
        Principal moments of inertia [j_x, j_y, j_z], kg·m².
    out : ndarray, shape (3,)
        Receives ω̇, rad/s².
    """
    wx, wy, wz = w[0], w[1], w[2]
    jx, jy, jz = J[0], J[1], J[2]
    out[0] = (torque[0] - (wy * jz * wz - wz * jy * wy)) / jx
    out[1] = (torque[1] - (wz * jx * wx - wx * jz * wz)) / jy
    out[2] = (torque[2] - (wx * jy * wy - wy * jx * wx)) / jz


@numba.njit(cache=True)
def _rotor_wrench_batch(N, theta, r, eps, V, W, F, M):
    for j in range(N.shape[0]):
        add_rotor_wrench(N[j], theta, r, eps, V[j], W[j], F[j], M[j])


@numba.njit(cache=True)
def _euler_batch(M, W, J, out):
    for j in range(M.shape[0]):
        euler_kernel(M[j], W[j], J, out[j])


def _rows(a: np.ndarray, batch: tuple[int, ...], width: int) -> np.ndarray:
    """``a`` broadcast to (*batch, width) as a contiguous (m, width) float array."""
    a = np.broadcast_to(np.asarray(a, dtype=float), (*batch, width))
    return np.ascontiguousarray(a.reshape(-1, width))


def rotor_wrench(
    n: np.ndarray, theta: np.ndarray, r: np.ndarray, eps: np.ndarray, v: np.ndarray,
    w: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The rotors' body force and torque for arrays of samples (see `add_rotor_wrench`).

    Parameters
    ----------
    n : ndarray, shape (..., k)
        Rotor speeds, rad/s.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI.
    r : ndarray, shape (k, 3)
        Rotor positions, m, body frame.
    eps : ndarray, shape (k,)
        Spin directions ε_i, ±1.
    v, w : ndarray, shape (..., 3)
        Body velocity v_B (m/s) and body rates ω (rad/s); broadcast against ``n``.

    Returns
    -------
    force : ndarray, shape (..., 3)
        Σ F_i, N.
    torque : ndarray, shape (..., 3)
        Σ (M_i + r_i × F_i), N·m.
    """
    n = np.asarray(n, dtype=float)
    k = n.shape[-1]
    batch = np.broadcast_shapes(n.shape[:-1], np.shape(v)[:-1], np.shape(w)[:-1])
    N = _rows(n, batch, k)
    F = np.zeros((N.shape[0], 3))
    M = np.zeros((N.shape[0], 3))
    _rotor_wrench_batch(N, np.ascontiguousarray(theta, dtype=float),
                        np.ascontiguousarray(r, dtype=float),
                        np.ascontiguousarray(eps, dtype=float),
                        _rows(v, batch, 3), _rows(w, batch, 3), F, M)
    return F.reshape(*batch, 3), M.reshape(*batch, 3)


def euler_acceleration(torque: np.ndarray, w: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Paper Eq. euler for arrays of samples (see `euler_kernel`).

    Parameters
    ----------
    torque : ndarray, shape (..., 3)
        Body torque M_B, N·m.
    w : ndarray, shape (..., 3)
        Body rates ω, rad/s.
    J : ndarray, shape (3,)
        Principal moments of inertia, kg·m².

    Returns
    -------
    ndarray, shape (..., 3)
        ω̇, rad/s².
    """
    batch = np.broadcast_shapes(np.shape(torque)[:-1], np.shape(w)[:-1])
    M = _rows(torque, batch, 3)
    out = np.empty_like(M)
    _euler_batch(M, _rows(w, batch, 3), np.ascontiguousarray(J, dtype=float), out)
    return out.reshape(*batch, 3)
