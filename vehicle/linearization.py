"""Error-state linearisation of the multirotor model (paper Section "One-Step Propagation").

One implementation serves the planner's belief propagation and the estimator's EKF, so
the covariance the planner predicts is the one the estimator reaches.

Error state δx, shape (12 + P,): [δp, δv_B, δφ, δω, δθ̃] with the attitude error in the
body frame, ``q = q̂ ⊗ Exp(δφ)``, and the P estimated quantities in scaled units,
``θ = θ̂ + s ⊙ δθ̃`` with a fixed positive scale s (by default the nominal θ), so that
a covariance stays well conditioned whether c_T is 1e-5 or 2e-8. The first six are the
paper's θ (`E_THETA`); a model with nuisance quantities
(`mavsysid.vehicle.parameters.EstimatedQuantity`) carries theirs after them: each enters
the dynamics as ``value × basis`` of its term, a body wrench evaluated along the states
(`ErrorStateModel.extra_basis`), so its Jacobian columns are that basis through 1/m and
J⁻¹ (`extra_columns_kernel`).

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
from mavsysid.vehicle.effect_base import EffectInputs
from mavsysid.vehicle.error_jacobian import jacobian_kernel
from mavsysid.vehicle.parameters import PAPER_THETA, EstimatedQuantity
from mavsysid.vehicle.rotation import quat_conjugate, quat_exp, quat_log, quat_multiply

__all__ = [
    "E_ATT",
    "E_POS",
    "E_RATE",
    "E_THETA",
    "E_VEL",
    "MEAS_DIM",
    "NOISE_DIM",
    "STATE_ERROR_DIM",
    "ErrorStateModel",
    "extra_columns_kernel",
    "extra_wrench_kernel",
    "initial_state_sigma",
    "jacobian_kernel",
    "transition_kernel",
]

#: Error-state entries of the vehicle's state (position, velocity, attitude, rates).
STATE_ERROR_DIM = 12
NOISE_DIM = 6
MEAS_DIM = 6
E_POS = slice(0, 3)
E_VEL = slice(3, 6)
E_ATT = slice(6, 9)
E_RATE = slice(9, 12)
#: The paper's θ in every error state (nuisance quantities follow).
E_THETA = slice(STATE_ERROR_DIM, STATE_ERROR_DIM + len(PAPER_THETA))


def initial_state_sigma(
    position_sigma: float, attitude_sigma: float, dt: float
) -> tuple[float, float, float, float]:
    """σ of the state when estimation starts: from the first pose and a difference of two.

    Shared by the estimator (which initialises this way) and the planner (which must
    predict the covariance the estimator will reach).

    Parameters
    ----------
    position_sigma : float
        Pose position noise σ, m.
    attitude_sigma : float
        Pose attitude noise σ, rad.
    dt : float
        Pose sample interval, s.

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
    theta_scale : ndarray, shape (P,)
        Units of the parameter error state; positive.
    extras : tuple of EstimatedQuantity
        Nuisance quantities estimated after the paper's θ (empty: the paper's model).
    """

    config: VehicleConfig
    theta_scale: np.ndarray
    extras: tuple[EstimatedQuantity, ...] = ()

    @classmethod
    def for_vehicle(
        cls, config: VehicleConfig, theta_scale: np.ndarray | None = None,
        extras: tuple[EstimatedQuantity, ...] | None = None,
    ) -> ErrorStateModel:
        """Model with parameter units ``theta_scale`` (default: |nominal θ|, 1 where zero;
        a nuisance quantity's |nominal|, else its prior σ).

        Parameters
        ----------
        config : VehicleConfig
            The vehicle.
        theta_scale : ndarray, shape (P,), optional
            Unit of each quantity's error state, SI.
        extras : tuple of EstimatedQuantity, optional
            Nuisance quantities after the paper's θ (default: the config's
            ``extra_quantities``).
        """
        extras = tuple(config.extra_quantities if extras is None else extras)
        if theta_scale is None:
            nominal = np.abs(np.concatenate([config.theta, [q.nominal for q in extras]]))
            fallback = np.array([1.0] * len(PAPER_THETA) + [
                q.prior_sigma if np.isfinite(q.prior_sigma) and q.prior_sigma > 0 else 1.0
                for q in extras])
            theta_scale = np.where(nominal > 0.0, nominal, fallback)
        theta_scale = np.asarray(theta_scale, dtype=float).reshape(len(PAPER_THETA) + len(extras))
        if np.any(theta_scale <= 0.0):
            raise ValueError("theta_scale must be positive")
        return cls(config, theta_scale, extras)

    @property
    def parameter_count(self) -> int:
        """P: the paper's θ and the nuisance quantities."""
        return len(PAPER_THETA) + len(self.extras)

    @property
    def dim(self) -> int:
        """Length of the error state, 12 + P."""
        return STATE_ERROR_DIM + self.parameter_count

    @property
    def parameter_slice(self) -> slice:
        """Where the P quantities sit in the error state."""
        return slice(STATE_ERROR_DIM, self.dim)

    def extra_basis(self, x: np.ndarray, n: np.ndarray, theta: np.ndarray,
                    t: np.ndarray | None = None) -> np.ndarray:
        """Each nuisance quantity's wrench per unit value, shape (N, 6, E): force (N), torque.

        Parameters
        ----------
        x : ndarray, shape (N, 13)
            States the terms are evaluated at.
        n : ndarray, shape (N, k)
            Rotor speeds, rad/s.
        theta : ndarray, shape (N, P) or (P,)
            Quantities, SI (the terms see the paper's θ).
        t : ndarray, shape (N,), optional
            Time since the flight's start, s (0 when not given).
        """
        x = np.asarray(x, dtype=float).reshape(-1, x.shape[-1])
        N = x.shape[0]
        out = np.zeros((N, 6, len(self.extras)))
        if not self.extras:
            return out
        th = np.broadcast_to(np.asarray(theta, float), (N, self.parameter_count))
        cfg = self.config
        inputs = EffectInputs(
            t=np.zeros(N) if t is None else np.asarray(t, float), position=x[:, 0:3],
            quaternion=x[:, 6:10], velocity=x[:, 3:6], rates=x[:, 10:13],
            rotor_speeds=np.asarray(n, float).reshape(N, -1), theta=th[0, :len(PAPER_THETA)],
            rotor_positions=np.asarray(cfg.rotor_positions, float),
            rotor_directions=np.asarray(cfg.rotor_directions, float))
        for e, quantity in enumerate(self.extras):
            assert quantity.term is not None
            force, torque = quantity.term.wrench_basis(inputs)
            out[:, 0:3, e], out[:, 3:6, e] = force, torque
        return out

    # -- dynamics ---------------------------------------------------------------------

    def continuous(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray, t: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Continuous Jacobians of the error dynamics δẋ = A δx + G w.

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            Linearisation states.
        n : ndarray, shape (..., k)
            Rotor speeds, rad/s.
        theta : ndarray, shape (..., P) or (P,)
            Quantities (SI).
        t : ndarray, shape (...), optional
            Time since the flight's start, s, for time-dependent nuisance terms.

        Returns
        -------
        A : ndarray, shape (..., D, D)
            D = 12 + P (`dim`).
        G : ndarray, shape (..., D, 6)
        """
        X, N, Th, basis, batch = self._batch(x, n, theta, t)
        d = self.dim
        A = np.empty((X.shape[0], d, d))
        G = np.empty((X.shape[0], d, NOISE_DIM))
        _jacobian_batch(X, N, Th, basis, *self.kernel_args(), A, G)
        return A.reshape(*batch, d, d), G.reshape(*batch, d, NOISE_DIM)

    def process_noise_density(self) -> np.ndarray:
        """Qc = diag(σ_F² I₃, σ_M² I₃), shape (6, 6), in N²·s and N²·m²·s."""
        nz = self.config.noise
        return np.diag([nz.force_density**2] * 3 + [nz.moment_density**2] * 3)

    def discrete(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray, dt: float,
        t: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Discrete transition F_k and process noise Q_k over a step ``dt`` (paper Eq. prior).

        F_k = exp(A dt) (4th-order Taylor series of exp(A dt/2), squared); Q_k by
        Simpson's rule on ∫ Φ G Qc Gᵀ Φᵀ (see `transition_kernel`).

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            Nominal state.
        n : ndarray, shape (..., k)
            Rotor speeds, rad/s.
        theta : ndarray, shape (..., P)
            Quantities, SI.
        dt : float
            Step, s.
        t : ndarray, shape (...), optional
            Time since the flight's start, s, for time-dependent nuisance terms.

        Returns
        -------
        F, Q : ndarray, shape (..., D, D)
        """
        X, N, Th, basis, batch = self._batch(x, n, theta, t)
        d = self.dim
        F = np.empty((X.shape[0], d, d))
        Q = np.empty_like(F)
        _discrete_batch(X, N, Th, basis, *self.kernel_args(), self.process_noise_density(),
                        float(dt), F, Q)
        return F.reshape(*batch, d, d), Q.reshape(*batch, d, d)

    def kernel_args(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(mass, rotor positions (k, 3), directions (k,), θ scale (P,)) for the kernels."""
        cfg = self.config
        return (float(cfg.mass), np.ascontiguousarray(cfg.rotor_positions),
                np.ascontiguousarray(cfg.rotor_directions),
                np.ascontiguousarray(self.theta_scale, dtype=float))

    def _batch(
        self, x: np.ndarray, n: np.ndarray, theta: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]:
        x = np.asarray(x, dtype=float)
        batch = x.shape[:-1]
        k = self.config.rotor_count
        X = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        b = X.shape[0]
        N = np.ascontiguousarray(np.broadcast_to(np.asarray(n, float), (*batch, k)).reshape(b, k))
        p = self.parameter_count
        th = np.broadcast_to(np.asarray(theta, float), (*batch, p))
        Th = np.ascontiguousarray(th.reshape(b, p))
        times = None if t is None else np.broadcast_to(np.asarray(t, float), batch).reshape(b)
        basis = np.ascontiguousarray(self.extra_basis(X, N, Th, times))
        return X, N, Th, basis, batch

    # -- measurement ------------------------------------------------------------------

    def measurement_covariance(self) -> np.ndarray:
        """R = diag(σ_p² I₃, σ_φ² I₃), shape (6, 6), in m² and rad²."""
        nz = self.config.noise
        return np.diag([nz.position_sigma**2] * 3 + [nz.attitude_sigma**2] * 3)

    @staticmethod
    def measure(x: np.ndarray) -> np.ndarray:
        """Noise-free measurement h(x) = [p, q], shape (..., 13) → (..., 7).

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            State.
        """
        x = np.asarray(x, dtype=float)
        return np.concatenate([x[..., POS], x[..., ATT]], axis=-1)

    # -- error-state algebra ----------------------------------------------------------

    def inject(
        self, x: np.ndarray, theta: np.ndarray, dx: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """x ⊞ δx: apply an error state to a nominal state and θ.

        Parameters
        ----------
        x : ndarray, shape (..., 13)
            Nominal state.
        theta : ndarray, shape (..., P)
            Nominal quantities, SI.
        dx : ndarray, shape (..., D)
            Error state.

        Returns
        -------
        x : ndarray, shape (..., 13)
        theta : ndarray, shape (..., P)
        """
        x = np.array(x, dtype=float)
        dx = np.asarray(dx, dtype=float)
        x[..., POS] += dx[..., E_POS]
        x[..., VEL] += dx[..., E_VEL]
        x[..., ATT] = quat_multiply(x[..., ATT], quat_exp(dx[..., E_ATT]))
        x[..., RATE] += dx[..., E_RATE]
        theta = np.asarray(theta, dtype=float) + self.theta_scale * dx[..., self.parameter_slice]
        return x, theta

    def difference(
        self, x: np.ndarray, theta: np.ndarray, x_ref: np.ndarray, theta_ref: np.ndarray
    ) -> np.ndarray:
        """δx = (x, θ) ⊟ (x_ref, θ_ref), shape (..., D); the inverse of `inject`.

        Parameters
        ----------
        x, x_ref : ndarray, shape (..., 13)
            States.
        theta, theta_ref : ndarray, shape (..., P)
            Quantities, SI.
        """
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
        """The P×P block of the quantities of an error-state covariance, in SI units.

        Parameters
        ----------
        P : ndarray, shape (..., D, D)
            Error-state covariance.
        """
        P = np.asarray(P, dtype=float)
        s = self.theta_scale
        block = self.parameter_slice
        return P[..., block, block] * s[:, None] * s[None, :]


@numba.njit(cache=True)
def transition_kernel(A, G, Qc, dt, F, Q):
    """F = exp(A dt) and Q = ∫₀^dt Φ(s) G Qc Gᵀ Φ(s)ᵀ ds, into F and Q.

    exp(A dt/2) by a 4th-order Taylor series (Horner), squared for F. Q by Simpson's
    rule, exact for the cubic growth of position and attitude variance under force and
    moment noise (the trapezoidal rule overstates it by half).

    Parameters
    ----------
    A : ndarray, shape (D, D)
        Continuous error-state Jacobian.
    G : ndarray, shape (D, 6)
        Noise input matrix.
    Qc : ndarray, shape (6, 6)
        Continuous noise density.
    dt : float
        Step, s.
    F : ndarray, shape (D, D)
        Receives the transition.
    Q : ndarray, shape (D, D)
        Receives the process noise.
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
def extra_columns_kernel(basis, J, mass, scale, A):
    """The nuisance quantities' columns of A: δv̇ = F_e/m, δω̇ = J⁻¹ M_e per scaled unit.

    Parameters
    ----------
    basis : ndarray, shape (6, E)
        Each quantity's body force (N) and torque (N·m) per unit value at this state.
    J : ndarray, shape (3,)
        Principal inertia, kg·m².
    mass : float
        kg.
    scale : ndarray, shape (6 + E,)
        Units of the quantities' error states.
    A : ndarray, shape (18 + E, 18 + E)
        Receives the columns 18 … 18 + E − 1 (its other columns set by `jacobian_kernel`).
    """
    first = A.shape[1] - basis.shape[1]
    for e in range(basis.shape[1]):
        s = scale[first - 12 + e]
        for p in range(3):
            A[3 + p, first + e] = basis[p, e] / mass * s
            A[9 + p, first + e] = basis[3 + p, e] / J[p] * s


@numba.njit(cache=True)
def extra_wrench_kernel(w, basis, values, out):
    """out = w + basis @ values: a known wrench plus the nuisance quantities', (6,).

    Parameters
    ----------
    w : ndarray, shape (6,)
        Body force (N) and torque (N·m) already known (effects; zeros: none).
    basis : ndarray, shape (6, E)
        Each quantity's wrench per unit value.
    values : ndarray, shape (E,)
        The quantities, SI.
    out : ndarray, shape (6,)
        Receives the sum.
    """
    for i in range(6):
        total = w[i]
        for e in range(values.shape[0]):
            total += basis[i, e] * values[e]
        out[i] = total


@numba.njit(cache=True)
def _jacobian_batch(X, N, Th, basis, mass, r, eps, scale, A, G):
    for j in range(X.shape[0]):
        jacobian_kernel(X[j], N[j], Th[j], mass, r, eps, scale, A[j], G[j])
        extra_columns_kernel(basis[j], Th[j, 3:6], mass, scale, A[j])


@numba.njit(cache=True)
def _discrete_batch(X, N, Th, basis, mass, r, eps, scale, Qc, dt, F, Q):
    A = np.empty((F.shape[1], F.shape[2]))
    G = np.empty((F.shape[1], Qc.shape[0]))
    for j in range(X.shape[0]):
        jacobian_kernel(X[j], N[j], Th[j], mass, r, eps, scale, A, G)
        extra_columns_kernel(basis[j], Th[j, 3:6], mass, scale, A)
        transition_kernel(A, G, Qc, dt, F[j], Q[j])
