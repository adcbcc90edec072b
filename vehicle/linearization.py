"""Error-state linearisation of the multirotor model (paper Section "One-Step Propagation").

One implementation serves the planner's belief propagation and the estimator's EKF, so
the covariance the planner predicts is the one the estimator reaches.

Error state δx, shape (18,): [δp, δv_B, δφ, δω, δθ̃] with the attitude error in the
body frame, ``q = q̂ ⊗ Exp(δφ)``, and the parameters in scaled units,
``θ = θ̂ + s ⊙ δθ̃`` with a fixed positive scale s (by default the nominal θ), so that
a covariance stays well conditioned whether c_T is 1e-5 or 2e-8.

Process noise w, shape (6,): unmodelled body force (N) and moment (N·m), white with
densities from the vehicle's ``[noise]``. Measurement: motion-capture position and
attitude, ``q_meas = q ⊗ Exp(φ)``; the residual is [p_meas - p̂, Log(q̂⁻¹ ⊗ q_meas)].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vehicle.config import GRAVITY, VehicleConfig
from vehicle.dynamics import ATT, POS, RATE, VEL
from vehicle.rotation import quat_conjugate, quat_exp, quat_log, quat_multiply, quat_to_matrix, skew

__all__ = [
    "ERROR_DIM",
    "E_ATT",
    "E_POS",
    "E_RATE",
    "E_THETA",
    "E_VEL",
    "MEAS_DIM",
    "NOISE_DIM",
    "ErrorStateModel",
]

ERROR_DIM = 18
NOISE_DIM = 6
MEAS_DIM = 6
E_POS = slice(0, 3)
E_VEL = slice(3, 6)
E_ATT = slice(6, 9)
E_RATE = slice(9, 12)
E_THETA = slice(12, 18)

_D = np.diag([1.0, 1.0, 0.0])  # rotor drag acts in the rotor plane only (paper Eq. drag)
_E3 = np.array([0.0, 0.0, 1.0])
_G = np.array([0.0, 0.0, -GRAVITY])


@dataclass(frozen=True)
class ErrorStateModel:
    """The linearised model of one vehicle.

    Attributes
    ----------
    config : VehicleConfig
        Mass, rotor geometry and noise.
    theta_scale : ndarray, shape (6,)
        Units of the parameter error state; positive.
    """

    config: VehicleConfig
    theta_scale: np.ndarray

    @classmethod
    def for_vehicle(
        cls, config: VehicleConfig, theta_scale: np.ndarray | None = None
    ) -> ErrorStateModel:
        """Model with parameter units ``theta_scale`` (default: |nominal θ|, 1 where zero)."""
        if theta_scale is None:
            theta_scale = np.abs(config.theta)
            theta_scale = np.where(theta_scale > 0.0, theta_scale, 1.0)
        theta_scale = np.asarray(theta_scale, dtype=float).reshape(6)
        if np.any(theta_scale <= 0.0):
            raise ValueError("theta_scale must be positive")
        return cls(config, theta_scale)

    # -- dynamics ---------------------------------------------------------------------

    def continuous(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Continuous Jacobians of the error dynamics δẋ = A δx + G w.

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            Linearisation states.
        n : ndarray, shape (..., k)
            Rotor speeds, rad/s.
        theta : ndarray, shape (..., 6) or (6,)
            Parameters (SI).

        Returns
        -------
        A : ndarray, shape (..., 18, 18)
        G : ndarray, shape (..., 18, 6)
        """
        x = np.asarray(x, dtype=float)
        batch = x.shape[:-1]
        x = x.reshape(-1, x.shape[-1])
        b = x.shape[0]
        k = self.config.rotor_count
        n = np.broadcast_to(np.asarray(n, dtype=float), (*batch, k)).reshape(b, k)
        th = np.broadcast_to(np.asarray(theta, dtype=float), (*batch, 6)).reshape(b, 6)
        m = self.config.mass
        r = self.config.rotor_positions
        eps = self.config.rotor_directions
        c_T, c_D, c_M = th[:, 0:1], th[:, 1:2], th[:, 2:3]
        J = th[:, 3:6]

        R = quat_to_matrix(x[:, ATT])
        v = x[:, VEL]
        w = x[:, RATE]
        n2 = n * n
        T = c_T * n2  # (b, k) rotor thrusts
        hub = v[:, None, :] + np.cross(w[:, None, :], r[None, :, :])  # v_B + ω × r_i
        hub_d = hub @ _D
        dF_dcT_i = n2[..., None] * (_E3 - c_D[..., None] * hub_d)  # (b, k, 3)
        dF_dcD_i = -T[..., None] * hub_d
        F_i = c_T[..., None] * dF_dcT_i
        M = np.sum(np.cross(r, F_i), axis=1) + np.outer(-(n2 @ eps), _E3) * c_M
        Jw = J * w
        w_dot = (M - np.cross(w, Jw)) / J

        Tr = T @ r  # Σ T_i r_i, (b, 3)
        rx = skew(r)  # (k, 3, 3)
        dF_dv = -(c_D * T.sum(axis=1, keepdims=True))[..., None] * _D
        dF_dw = c_D[..., None] * (_D @ skew(Tr))
        dM_dv = -c_D[..., None] * (skew(Tr) @ _D)
        dM_dw = c_D[..., None] * np.einsum("bk,kij->bij", T, rx @ _D @ rx)

        A = np.zeros((b, ERROR_DIM, ERROR_DIM))
        # ṗ = R v_B with R = R̂ (I + [δφ]×)
        A[:, E_POS, E_VEL] = R
        A[:, E_POS, E_ATT] = -R @ skew(v)
        # Paper Eq. newton
        A[:, E_VEL, E_VEL] = dF_dv / m - skew(w)
        A[:, E_VEL, E_ATT] = skew(np.einsum("bji,j->bi", R, _G))
        A[:, E_VEL, E_RATE] = dF_dw / m + skew(v)
        A[:, E_VEL, 12] = dF_dcT_i.sum(axis=1) / m
        A[:, E_VEL, 13] = dF_dcD_i.sum(axis=1) / m
        # Attitude error kinematics: δφ̇ = -ω × δφ + δω
        A[:, E_ATT, E_ATT] = -skew(w)
        A[:, E_ATT, E_RATE] = np.eye(3)
        # Paper Eq. euler
        Jinv = (1.0 / J)[..., None]
        J_mat = J[:, :, None] * np.eye(3)
        A[:, E_RATE, E_VEL] = Jinv * dM_dv
        A[:, E_RATE, E_RATE] = Jinv * (dM_dw - skew(w) @ J_mat + skew(Jw))
        A[:, E_RATE, 12] = np.sum(np.cross(r, dF_dcT_i), axis=1) / J
        A[:, E_RATE, 13] = np.sum(np.cross(r, dF_dcD_i), axis=1) / J
        A[:, E_RATE, 14] = np.outer(-(n2 @ eps), _E3) / J
        for a in range(3):
            e_a = np.eye(3)[a]
            col = -np.cross(w, e_a) * w[:, a : a + 1] / J
            col[:, a] -= w_dot[:, a] / J[:, a]
            A[:, E_RATE, 15 + a] = col
        A[:, :, E_THETA] *= self.theta_scale

        G = np.zeros((b, ERROR_DIM, NOISE_DIM))
        G[:, E_VEL, 0:3] = np.eye(3) / m
        G[:, E_RATE, 3:6] = Jinv * np.eye(3)
        return A.reshape(*batch, ERROR_DIM, ERROR_DIM), G.reshape(*batch, ERROR_DIM, NOISE_DIM)

    def process_noise_density(self) -> np.ndarray:
        """Qc = diag(σ_F² I₃, σ_M² I₃), shape (6, 6), in N²·s and N²·m²·s."""
        nz = self.config.noise
        return np.diag([nz.force_density**2] * 3 + [nz.moment_density**2] * 3)

    def discrete(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray, dt: float, order: int = 4
    ) -> tuple[np.ndarray, np.ndarray]:
        """Discrete transition F_k and process noise Q_k over a step ``dt`` (paper Eq. prior).

        F_k = exp(A dt) by its Taylor series to ``order``; Q_k by the trapezoidal rule,
        ½ (F G Qc Gᵀ Fᵀ + G Qc Gᵀ) dt.

        Returns
        -------
        F, Q : ndarray, shape (..., 18, 18)
        """
        A, G = self.continuous(x, n, theta)
        Adt = A * dt
        eye = np.eye(ERROR_DIM)
        F = eye + Adt / order
        for i in range(order - 1, 0, -1):  # Horner: I + Adt (I + Adt/2 (I + …))
            F = eye + (Adt @ F) / i
        GQG = G @ self.process_noise_density() @ np.swapaxes(G, -1, -2)
        Q = 0.5 * dt * (F @ GQG @ np.swapaxes(F, -1, -2) + GQG)
        return F, Q

    # -- measurement ------------------------------------------------------------------

    @staticmethod
    def measurement_jacobian() -> np.ndarray:
        """H, shape (6, 18): the residual depends on δp and δφ with unit gain."""
        H = np.zeros((MEAS_DIM, ERROR_DIM))
        H[0:3, E_POS] = np.eye(3)
        H[3:6, E_ATT] = np.eye(3)
        return H

    def measurement_covariance(self) -> np.ndarray:
        """R = diag(σ_p² I₃, σ_φ² I₃), shape (6, 6), in m² and rad²."""
        nz = self.config.noise
        return np.diag([nz.position_sigma**2] * 3 + [nz.attitude_sigma**2] * 3)

    @staticmethod
    def measure(x: np.ndarray) -> np.ndarray:
        """Noise-free measurement h(x) = [p, q], shape (..., 13) → (..., 7)."""
        x = np.asarray(x, dtype=float)
        return np.concatenate([x[..., POS], x[..., ATT]], axis=-1)

    @staticmethod
    def residual(z: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Measurement residual [p_meas - p̂, Log(q̂⁻¹ ⊗ q_meas)], shape (..., 6)."""
        z = np.asarray(z, dtype=float)
        x = np.asarray(x, dtype=float)
        dq = quat_multiply(quat_conjugate(x[..., ATT]), z[..., 3:7])
        return np.concatenate([z[..., 0:3] - x[..., POS], quat_log(dq)], axis=-1)

    # -- error-state algebra ----------------------------------------------------------

    def inject(
        self, x: np.ndarray, theta: np.ndarray, dx: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """x ⊞ δx: apply an error state to a nominal state and θ.

        Returns
        -------
        x : ndarray, shape (..., 13)
        theta : ndarray, shape (..., 6)
        """
        x = np.array(x, dtype=float)
        dx = np.asarray(dx, dtype=float)
        x[..., POS] += dx[..., E_POS]
        x[..., VEL] += dx[..., E_VEL]
        x[..., ATT] = quat_multiply(x[..., ATT], quat_exp(dx[..., E_ATT]))
        x[..., RATE] += dx[..., E_RATE]
        theta = np.asarray(theta, dtype=float) + self.theta_scale * dx[..., E_THETA]
        return x, theta

    def difference(
        self, x: np.ndarray, theta: np.ndarray, x_ref: np.ndarray, theta_ref: np.ndarray
    ) -> np.ndarray:
        """δx = (x, θ) ⊟ (x_ref, θ_ref), shape (..., 18); the inverse of `inject`."""
        x = np.asarray(x, dtype=float)
        x_ref = np.asarray(x_ref, dtype=float)
        dq = quat_multiply(quat_conjugate(x_ref[..., ATT]), x[..., ATT])
        return np.concatenate(
            [
                x[..., POS] - x_ref[..., POS],
                x[..., VEL] - x_ref[..., VEL],
                quat_log(dq),
                x[..., RATE] - x_ref[..., RATE],
                (np.asarray(theta, float) - np.asarray(theta_ref, float)) / self.theta_scale,
            ],
            axis=-1,
        )

    def parameter_covariance_si(self, P: np.ndarray) -> np.ndarray:
        """The 6×6 θ block of an error-state covariance P, converted to SI units."""
        P = np.asarray(P, dtype=float)
        s = self.theta_scale
        return P[..., E_THETA, E_THETA] * s[:, None] * s[None, :]
