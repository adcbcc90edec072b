"""What an ideal IMU on the vehicle reads: body rates and specific force, at its position.

An accelerometer measures the specific force, the non-gravitational force per unit mass,
f = a − g in the world frame, in its own (body) frame: [0, 0, +9.81] m/s² (FLU) level at
rest, F_B/m at the centre of gravity in flight, where F_B is the body force of
`mavsysid.vehicle.dynamics` (rotor thrust and drag, plus any extra force). An IMU at p
(body FLU, from the CoG) on a rigid body also feels the rotation:

    f_imu = F_B/m + ω̇ × p + ω × (ω × p),    gyro = ω

with ω̇ from Euler's equation. The rotor wrench and Euler's equation are the model's
(`mavsysid.vehicle.mav_model.add_rotor_wrench`, `euler_kernel`); `imu_kernel` is the
compiled reading of one sample (a simulator calls it at every tick), `imu_reading` the
same for arrays of samples. Autopilots log the same quantities in body FRD
(`mavsysid.vehicle.frames.flu_to_frd`): [0, 0, −9.81] level at rest.
"""

from __future__ import annotations

import numba
import numpy as np
from mavsysid.vehicle.effect_base import EffectInputs
from mavsysid.vehicle.mav_model import add_rotor_wrench, euler_kernel
from mavsysid.vehicle.parameters import EstimatedQuantity, QuantityTerm

__all__ = ["IMU_POSITION_SIGMA", "ImuBias", "ImuOffset", "imu_kernel", "imu_quantities",
           "imu_reading", "lever_arm_acceleration"]

#: Prior σ of an IMU's offset from the centre of gravity the vehicle file does not state, m
#: per axis: an autopilot or IMU board mounted near the centre of a small frame.
IMU_POSITION_SIGMA = 0.03


def lever_arm_acceleration(w: np.ndarray, w_dot: np.ndarray, position: np.ndarray) -> np.ndarray:
    """The specific force an IMU at ``position`` feels beyond the CoG's: ω̇ × p + ω × (ω × p).

    Parameters
    ----------
    w : ndarray, shape (..., 3)
        Body rates ω, rad/s.
    w_dot : ndarray, shape (..., 3)
        Angular acceleration ω̇, rad/s².
    position : array_like, shape (3,) or (..., 3)
        The IMU's offset from the CoG, m, body frame.

    Returns
    -------
    ndarray, shape (..., 3)
        m/s², body frame.
    """
    p = np.asarray(position, dtype=float)
    return np.cross(w_dot, p) + np.cross(w, np.cross(w, p))


@numba.njit(cache=True)
def imu_kernel(x, n, theta, mass, r, eps, force_ext, torque_ext, p, out):
    """The ideal [gyro, specific force] of one sample into ``out`` (6,), body frame.

    Parameters
    ----------
    x : ndarray, shape (13,)
        State [p, v_B, q, ω].
    n : ndarray, shape (k,)
        Rotor speeds, rad/s.
    theta : ndarray, shape (6,)
        θ, SI.
    mass : float
        kg.
    r : ndarray, shape (k, 3)
        Rotor positions, m.
    eps : ndarray, shape (k,)
        Spin directions ±1.
    force_ext, torque_ext : ndarray, shape (3,)
        Extra body force (N) and torque (N·m).
    p : ndarray, shape (3,)
        The IMU's offset from the CoG, m.
    out : ndarray, shape (6,)
        Receives ω (rad/s) and f at the IMU (m/s²).
    """
    force = force_ext.copy()
    torque = torque_ext.copy()
    w = x[10:13]
    add_rotor_wrench(n, theta, r, eps, x[3:6], w, force, torque)
    w_dot = np.empty(3)
    euler_kernel(torque, w, theta[3:6], w_dot)
    # ω × p, then ω × (ω × p) and ω̇ × p.
    cx = w[1] * p[2] - w[2] * p[1]
    cy = w[2] * p[0] - w[0] * p[2]
    cz = w[0] * p[1] - w[1] * p[0]
    out[0], out[1], out[2] = w[0], w[1], w[2]
    out[3] = force[0] / mass + (w_dot[1] * p[2] - w_dot[2] * p[1]) + (w[1] * cz - w[2] * cy)
    out[4] = force[1] / mass + (w_dot[2] * p[0] - w_dot[0] * p[2]) + (w[2] * cx - w[0] * cz)
    out[5] = force[2] / mass + (w_dot[0] * p[1] - w_dot[1] * p[0]) + (w[0] * cy - w[1] * cx)


@numba.njit(cache=True)
def _imu_batch(X, N, theta, mass, r, eps, F, T, p, out):
    for j in range(X.shape[0]):
        imu_kernel(X[j], N[j], theta, mass, r, eps, F[j], T[j], p, out[j])


def _rows(a: np.ndarray | None, batch: tuple[int, ...], width: int) -> np.ndarray:
    """``a`` (zeros if None) broadcast to a contiguous (m, width) float array."""
    a = np.zeros(width) if a is None else np.asarray(a, dtype=float)
    return np.ascontiguousarray(np.broadcast_to(a, (*batch, width)).reshape(-1, width))


def imu_reading(x: np.ndarray, n: np.ndarray, theta: np.ndarray, mass: float,
                rotor_positions: np.ndarray, rotor_directions: np.ndarray,
                force_ext: np.ndarray | None = None, torque_ext: np.ndarray | None = None,
                imu_position: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ideal gyro and accelerometer readings for states and rotor speeds.

    Parameters
    ----------
    x : ndarray, shape (..., 13)
        States [p, v_B, q, ω] (`mavsysid.vehicle.dynamics`).
    n : ndarray, shape (..., k)
        Rotor speeds, rad/s.
    theta : ndarray, shape (6,)
        θ = [c_T, c_D, c_M, j_x, j_y, j_z], SI.
    mass : float
        kg.
    rotor_positions : ndarray, shape (k, 3)
        m, body FLU.
    rotor_directions : ndarray, shape (k,)
        ±1.
    force_ext, torque_ext : ndarray, shape (3,) or (..., 3), optional
        Extra body force (N) and torque (N·m), e.g. a truth-side effect's; 0 if None.
    imu_position : array_like, shape (3,), optional
        The IMU's offset from the CoG, m, body FLU; at the CoG if None.

    Returns
    -------
    gyro : ndarray, shape (..., 3)
        ω, rad/s, body FLU.
    accel : ndarray, shape (..., 3)
        Specific force at the IMU, m/s², body FLU.
    """
    x = np.asarray(x, dtype=float)
    n = np.asarray(n, dtype=float)
    k = n.shape[-1]
    batch = np.broadcast_shapes(x.shape[:-1], n.shape[:-1])
    out = np.empty((int(np.prod(batch, dtype=int)), 6))
    _imu_batch(_rows(x, batch, 13), _rows(n, batch, k), np.ascontiguousarray(theta, dtype=float),
               float(mass), np.ascontiguousarray(rotor_positions, dtype=float),
               np.ascontiguousarray(rotor_directions, dtype=float), _rows(force_ext, batch, 3),
               _rows(torque_ext, batch, 3),
               np.zeros(3) if imu_position is None else np.asarray(imu_position, dtype=float),
               out)
    out = out.reshape(*batch, 6)
    return out[..., :3], out[..., 3:]


class ImuBias(QuantityTerm):
    """A constant bias of one axis of the gyro (rad/s) or the accelerometer (m/s²).

    Parameters
    ----------
    channel : {"gyro", "accel"}
    axis : int
        0, 1, 2 for x, y, z (body FLU).
    """

    def __init__(self, channel: str, axis: int) -> None:
        self.channel = channel  # type: ignore[misc]
        self.axis = axis

    def reading_basis(self, inputs: EffectInputs) -> np.ndarray:
        out = np.zeros((inputs.t.shape[0], 3))
        out[:, self.axis] = 1.0
        return out


class ImuOffset(QuantityTerm):
    """One coordinate of the IMU's offset p from the centre of gravity, m (body FLU): the
    accelerometer reads ω̇ × p + ω × (ω × p) beyond the centre's specific force.

    Parameters
    ----------
    axis : int
        0, 1, 2 for x, y, z.
    """

    channel = "accel"

    def __init__(self, axis: int) -> None:
        self.axis = axis

    def reading_basis(self, inputs: EffectInputs) -> np.ndarray:
        unit = np.zeros(3)
        unit[self.axis] = 1.0
        w_dot = (np.zeros_like(inputs.rates) if inputs.angular_acceleration is None
                 else inputs.angular_acceleration)
        return lever_arm_acceleration(inputs.rates, w_dot, unit)


def imu_quantities(gyro: bool, accel: bool, position_known: bool, gyro_bias_sigma: float,
                   accel_bias_sigma: float) -> tuple[EstimatedQuantity, ...]:
    """The nuisance quantities an IMU brings: its biases, and its offset where not stated.

    Parameters
    ----------
    gyro, accel : bool
        Which sensors the flight has.
    position_known : bool
        Whether the IMU's offset from the centre of gravity is stated (vehicle file or log);
        when not, its three coordinates are estimated from the accelerometer.
    gyro_bias_sigma, accel_bias_sigma : float
        Prior σ of the constant biases, rad/s and m/s² (the vehicle file's ``[noise]``).

    Returns
    -------
    tuple of EstimatedQuantity
        ``gyro_bias_x..z``, ``accel_bias_x..z``, ``imu_x..z``, as the flight calls for.
    """
    out: list[EstimatedQuantity] = []
    for present, channel, unit, sigma in ((gyro, "gyro", "rad/s", gyro_bias_sigma),
                                          (accel, "accel", "m/s²", accel_bias_sigma)):
        if present:
            out += [EstimatedQuantity(f"{channel}_bias_{a}", unit,
                                      f"constant bias of the {channel} about {a}",
                                      prior_sigma=sigma, term=ImuBias(channel, i))
                    for i, a in enumerate("xyz")]
    if accel and not position_known:
        out += [EstimatedQuantity(f"imu_{a}", "m", f"the IMU's offset from the centre of "
                                  f"gravity along {a}_B", prior_sigma=IMU_POSITION_SIGMA,
                                  term=ImuOffset(i))
                for i, a in enumerate("xyz")]
    return tuple(out)
