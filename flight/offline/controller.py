"""Geometric position controller (Lee et al. 2010, with Mellinger's flatness feed-forward).

Position loop: a_cmd = a_ref - k_p e_p - k_v e_v, thrust vector m (a_cmd - g) (plus the
predicted rotor drag, which the thrust must also overcome). Attitude loop on SO(3):

    e_R = ½ vee(R_dᵀ R - Rᵀ R_d),  e_ω = ω - Rᵀ R_d ω_d,
    M   = J (-k_R e_R - k_ω e_ω) + ω × J ω - J ([ω]× Rᵀ R_d ω_d - Rᵀ R_d ω̇_d),

with ω_d and ω̇_d from differential flatness of the reference. Gains are natural
frequencies and damping ratios, so one set works from a 30 g to a 3 kg vehicle. The
wrench is mixed as the vehicle file's ``[limits] allocation`` says
(`mavsysid.flight.offline.null_space_mixer`): with the model's A⁺ ("pseudo_inverse"), or
over the allocation null space ("exact"); at the rotor limits yaw torque is given up
first, then commands are clipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.flight.offline.null_space_mixer import (
    NullSpaceMixer,
    null_space_mix,
    null_space_mixer,
    pseudo_inverse_mix,
)
from mavsysid.vehicle.allocation import allocation_matrix, allocation_pinv
from mavsysid.vehicle.config import GRAVITY, VehicleConfig
from mavsysid.vehicle.flatness import flat_to_state
from mavsysid.vehicle.rotation import rotation_kernel
from mavsysid.vehicle.trajectory import Trajectory

__all__ = ["REFERENCE_DIM", "ControllerGains", "GeometricController", "reference_samples"]

#: Columns of a reference row: p (3), v (3), a (3), yaw, ω_d (3), ω̇_d (3) — world ENU / body.
REFERENCE_DIM = 16


@dataclass(frozen=True)
class ControllerGains:
    """Controller tuning as closed-loop natural frequencies (rad/s) and damping ratios.

    Attributes
    ----------
    position_frequency, position_damping : float
        Position loop natural frequency (rad/s) and damping ratio.
    attitude_frequency, attitude_damping : float
        Attitude loop natural frequency (rad/s) and damping ratio.
    max_tilt : float
        Largest commanded tilt, rad.
    drag_compensation : bool
        Feed the model's rotor drag forward.
    """

    position_frequency: float = 4.0
    position_damping: float = 1.0
    attitude_frequency: float = 20.0
    attitude_damping: float = 0.8
    max_tilt: float = math.radians(70.0)
    drag_compensation: bool = True


def reference_samples(
    trajectory: Trajectory, times: np.ndarray, config: VehicleConfig,
    theta: np.ndarray | None = None,
) -> np.ndarray:
    """Controller reference rows at ``times`` (s, shape (S,)), shape (S, 16).

    Parameters
    ----------
    trajectory : Trajectory
        The flight.
    times : ndarray, shape (S,)
        s.
    config : VehicleConfig
        The vehicle.
    theta : ndarray, shape (6,), optional
        θ, SI (default: the nominal).
    """
    flat = trajectory.flat_outputs(np.asarray(times, dtype=float))
    state = flat_to_state(flat, config, theta)
    return np.column_stack(
        [flat.position, flat.velocity, flat.acceleration, flat.yaw,
         state.body_rates, state.angular_acceleration]
    )


@numba.njit(cache=True)
def _wrench_kernel(x, ref, mass, J, c_D, gains):
    """Commanded wrench [T, τ_x, τ_y, τ_z] (N, N·m), shape (4,), for state x and reference row."""
    kp, kv, kR, kw, max_tilt, drag_comp = gains[0], gains[1], gains[2], gains[3], gains[4], gains[5]
    R = rotation_kernel(x[6:10])
    vB = x[3:6]
    w = x[10:13]
    vW = R @ vB

    f = np.empty(3)
    for i in range(3):
        a_cmd = ref[6 + i] - kp * (x[i] - ref[i]) - kv * (vW[i] - ref[3 + i])
        f[i] = mass * a_cmd
    f[2] += mass * GRAVITY
    if drag_comp > 0.0:
        # Rotor drag -T c_D (v_B)_xy must be overcome too; T ≈ |f| is close enough.
        T_est = np.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        for i in range(3):
            f[i] += T_est * c_D * (R[i, 0] * vB[0] + R[i, 1] * vB[1])
    # Keep the thrust pointing up and the tilt bounded.
    f[2] = max(f[2], 0.2 * mass * GRAVITY)
    horiz = np.sqrt(f[0] * f[0] + f[1] * f[1])
    hmax = f[2] * np.tan(max_tilt)
    if horiz > hmax:
        f[0] *= hmax / horiz
        f[1] *= hmax / horiz
    fn = np.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
    zd = f / fn
    yaw = ref[9]
    xc = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    yd = np.cross(zd, xc)
    yd /= np.sqrt(yd[0] * yd[0] + yd[1] * yd[1] + yd[2] * yd[2])
    xd = np.cross(yd, zd)
    Rd = np.empty((3, 3))
    for i in range(3):
        Rd[i, 0], Rd[i, 1], Rd[i, 2] = xd[i], yd[i], zd[i]
    thrust = f[0] * R[0, 2] + f[1] * R[1, 2] + f[2] * R[2, 2]

    E = Rd.T @ R - R.T @ Rd
    eR = 0.5 * np.array([E[2, 1], E[0, 2], E[1, 0]])
    RtRd = R.T @ Rd
    wd = RtRd @ ref[10:13]
    dwd = RtRd @ ref[13:16]
    Jw = J * w
    wxwd = np.cross(w, wd)
    M = J * (-kR * eR - kw * (w - wd)) + np.cross(w, Jw) - J * (wxwd - dwd)

    wrench = np.empty(4)
    wrench[0] = thrust
    wrench[1:] = M
    return wrench


@numba.njit(cache=True)
def _control_kernel(x, ref, mass, J, c_D, gains, pinv, n2_min, n2_max, out):
    """A⁺-mixed rotor-speed command into ``out`` (k,); returns True if any rotor was clipped."""
    w = _wrench_kernel(x, ref, mass, J, c_D, gains)
    return pseudo_inverse_mix(w, pinv, n2_min, n2_max, out)


@numba.njit(cache=True)
def _exact_control_kernel(x, ref, mass, J, c_D, gains, pinv, null, normals, lower, upper,
                          tol, n2_min, n2_max, out):
    """Null-space-mixed rotor-speed command into ``out`` (k,); True if yaw or a rotor saturated."""
    w = _wrench_kernel(x, ref, mass, J, c_D, gains)
    return null_space_mix(w, pinv, null, normals, lower, upper, tol, n2_min, n2_max, out)


class GeometricController:
    """Tracks reference rows (see `reference_samples`) with rotor-speed commands.

    Parameters
    ----------
    config : VehicleConfig
        Vehicle (mass, geometry, rotor limits).
    theta : ndarray, shape (6,), optional
        The controller's model of θ (allocation, inertia, drag); nominal by default.
    gains : ControllerGains, optional
    """

    def __init__(
        self, config: VehicleConfig, theta: np.ndarray | None = None,
        gains: ControllerGains | None = None,
    ) -> None:
        self.config = config
        self.gains = gains or ControllerGains()
        theta = config.theta if theta is None else np.asarray(theta, dtype=float)
        g = self.gains
        self._gains = np.array([
            g.position_frequency**2, 2.0 * g.position_damping * g.position_frequency,
            g.attitude_frequency**2, 2.0 * g.attitude_damping * g.attitude_frequency,
            g.max_tilt, 1.0 if g.drag_compensation else 0.0,
        ])
        self._mass = float(config.mass)
        self._J = np.ascontiguousarray(theta[3:6])
        self._c_D = float(theta[1])
        self._pinv = np.ascontiguousarray(allocation_pinv(config, theta))
        self._n2_min = config.limits.rotor_speed_min**2
        self._n2_max = config.limits.rotor_speed_max**2
        # "exact": the vehicle's mixer uses the allocation null space (see null_space_mixer).
        self._mixer: NullSpaceMixer | None = None
        if config.allocation == "exact":
            self._mixer = null_space_mixer(allocation_matrix(config, theta), self._pinv,
                                           self._n2_min, self._n2_max)

    def command(self, x: np.ndarray, reference: np.ndarray, out: np.ndarray) -> bool:
        """Write rotor-speed commands (rad/s, shape (k,)) for state x (13,) into ``out``.

        Returns True when a rotor command was clipped at a limit (or, with the exact
        mixer, yaw torque was given up).

        Parameters
        ----------
        x : ndarray, shape (13,)
            State [p, v_B, q, ω].
        reference : ndarray, shape (16,)
            Reference row (`reference_samples`).
        out : ndarray, shape (k,)
            Receives the rotor-speed commands, rad/s.
        """
        m = self._mixer
        if m is None:
            return _control_kernel(
                x, reference, self._mass, self._J, self._c_D, self._gains, self._pinv,
                self._n2_min, self._n2_max, out,
            )
        return _exact_control_kernel(
            x, reference, self._mass, self._J, self._c_D, self._gains, m.pinv, m.null,
            m.normals, m.lower, m.upper, m.tolerance, m.n2_min, m.n2_max, out,
        )
