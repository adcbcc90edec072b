"""Error-state linearisation of the multirotor model (paper Section "One-Step Propagation").

One implementation serves the planner's belief propagation and the estimator's EKF, so
the covariance the planner predicts is the one the estimator reaches.

Error state δx, shape (18,): [δp, δv_B, δφ, δω, δθ̃] with the attitude error in the
body frame, ``q = q̂ ⊗ Exp(δφ)``, and the parameters in scaled units,
``θ = θ̂ + s ⊙ δθ̃`` with a fixed positive scale s (by default the nominal θ), so that
a covariance stays well conditioned whether c_T is 1e-5 or 2e-8.

Process noise w, shape (6,): unmodelled body force (N) and moment (N·m), white with
densities from the vehicle's ``[noise]``. Measurement: motion-capture position and
attitude, ``q_meas = q ⊗ Exp(φ)``; its residual, its H and the covariance step that
uses them are in `mavsysid.vehicle.covariance`.

The Jacobian kernel itself is in `mavsysid.vehicle.error_jacobian`; it is re-exported
here with the transition kernel, so that the EKF and the planner import both from here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.vehicle.config_types import VehicleConfig
from mavsysid.vehicle.dynamics import ATT, POS, RATE, VEL
from mavsysid.vehicle.error_jacobian import jacobian_kernel
from mavsysid.vehicle.rotation import quat_conjugate, quat_exp, quat_log, quat_multiply

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
    "initial_state_sigma",
    "jacobian_kernel",
    "transition_kernel",
]

ERROR_DIM = 18
NOISE_DIM = 6
MEAS_DIM = 6
E_POS = slice(0, 3)
E_VEL = slice(3, 6)
E_ATT = slice(6, 9)
E_RATE = slice(9, 12)
E_THETA = slice(12, 18)



def initial_state_sigma(
    position_sigma: float, attitude_sigma: float, dt: float
) -> tuple[float, float, float, float]:
    """σ of the state when estimation starts: from the first pose and a difference of two.

    Shared by the estimator (which initialises this way) and the planner (which must
    predict the covariance the estimator will reach).

    Returns
    -------
    tuple of 4 float
        Position (m), velocity (m/s), attitude (rad) and body-rate (rad/s) σ.
    """
    return (3.0 * position_sigma, max(0.05, 3.0 * np.sqrt(2.0) * position_sigma / dt),
            3.0 * attitude_sigma, max(0.05, 3.0 * np.sqrt(2.0) * attitude_sigma / dt))


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
        X, N, Th, batch = self._batch(x, n, theta)
        A = np.empty((X.shape[0], ERROR_DIM, ERROR_DIM))
        G = np.empty((X.shape[0], ERROR_DIM, NOISE_DIM))
        _jacobian_batch(X, N, Th, *self.kernel_args(), A, G)
        return A.reshape(*batch, ERROR_DIM, ERROR_DIM), G.reshape(*batch, ERROR_DIM, NOISE_DIM)

    def process_noise_density(self) -> np.ndarray:
        """Qc = diag(σ_F² I₃, σ_M² I₃), shape (6, 6), in N²·s and N²·m²·s."""
        nz = self.config.noise
        return np.diag([nz.force_density**2] * 3 + [nz.moment_density**2] * 3)

    def discrete(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Discrete transition F_k and process noise Q_k over a step ``dt`` (paper Eq. prior).

        F_k = exp(A dt) (4th-order Taylor series of exp(A dt/2), squared); Q_k by
        Simpson's rule on ∫ Φ G Qc Gᵀ Φᵀ (see `transition_kernel`).

        Returns
        -------
        F, Q : ndarray, shape (..., 18, 18)
        """
        X, N, Th, batch = self._batch(x, n, theta)
        F = np.empty((X.shape[0], ERROR_DIM, ERROR_DIM))
        Q = np.empty_like(F)
        _discrete_batch(X, N, Th, *self.kernel_args(), self.process_noise_density(), float(dt),
                        F, Q)
        return F.reshape(*batch, ERROR_DIM, ERROR_DIM), Q.reshape(*batch, ERROR_DIM, ERROR_DIM)

    def kernel_args(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(mass, rotor positions (k, 3), directions (k,), θ scale (6,)) for the kernels."""
        cfg = self.config
        return (float(cfg.mass), np.ascontiguousarray(cfg.rotor_positions),
                np.ascontiguousarray(cfg.rotor_directions),
                np.ascontiguousarray(self.theta_scale, dtype=float))

    def _batch(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]:
        x = np.asarray(x, dtype=float)
        batch = x.shape[:-1]
        k = self.config.rotor_count
        X = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        b = X.shape[0]
        N = np.ascontiguousarray(np.broadcast_to(np.asarray(n, float), (*batch, k)).reshape(b, k))
        th = np.broadcast_to(np.asarray(theta, float), (*batch, 6))
        Th = np.ascontiguousarray(th.reshape(b, 6))
        return X, N, Th, batch

    # -- measurement ------------------------------------------------------------------

    def measurement_covariance(self) -> np.ndarray:
        """R = diag(σ_p² I₃, σ_φ² I₃), shape (6, 6), in m² and rad²."""
        nz = self.config.noise
        return np.diag([nz.position_sigma**2] * 3 + [nz.attitude_sigma**2] * 3)

    @staticmethod
    def measure(x: np.ndarray) -> np.ndarray:
        """Noise-free measurement h(x) = [p, q], shape (..., 13) → (..., 7)."""
        x = np.asarray(x, dtype=float)
        return np.concatenate([x[..., POS], x[..., ATT]], axis=-1)

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


@numba.njit(cache=True)
def transition_kernel(A, G, Qc, dt, F, Q):
    """F = exp(A dt) and Q = ∫₀^dt Φ(s) G Qc Gᵀ Φ(s)ᵀ ds, into F and Q.

    exp(A dt/2) by a 4th-order Taylor series (Horner), squared for F. Q by Simpson's
    rule, exact for the cubic growth of position and attitude variance under force and
    moment noise (the trapezoidal rule overstates it by half).
    """
    d = A.shape[0]
    Ah = A * (0.5 * dt)
    eye = np.eye(d)
    Fh = eye + Ah / 4.0
    for i in range(3, 0, -1):  # Horner: I + Ah (I + Ah/2 (I + Ah/3 (I + Ah/4)))
        Fh = eye + (Ah @ Fh) / i
    F[:] = Fh @ Fh
    GQG = G @ Qc @ G.T
    Q[:] = dt / 6.0 * (GQG + 4.0 * (Fh @ GQG @ Fh.T) + F @ GQG @ F.T)


@numba.njit(cache=True)
def _jacobian_batch(X, N, Th, mass, r, eps, scale, A, G):
    for j in range(X.shape[0]):
        jacobian_kernel(X[j], N[j], Th[j], mass, r, eps, scale, A[j], G[j])


@numba.njit(cache=True)
def _discrete_batch(X, N, Th, mass, r, eps, scale, Qc, dt, F, Q):
    A = np.empty((F.shape[1], F.shape[2]))
    G = np.empty((F.shape[1], Qc.shape[0]))
    for j in range(X.shape[0]):
        jacobian_kernel(X[j], N[j], Th[j], mass, r, eps, scale, A, G)
        transition_kernel(A, G, Qc, dt, F[j], Q[j])
