"""The parameter EKF (paper Sections "Robot Model and EKF" and "MAV Model"), on filterpy.

`ParameterEKF` subclasses `filterpy.kalman.ExtendedKalmanFilter` and keeps its API:
``x``, ``P``, ``F``, ``Q``, ``R``, ``y``, ``S``, ``SI``, ``K``, ``predict()``,
``update(z)``, ``log_likelihood``, ``mahalanobis``, ``x_prior``/``P_prior``,
``x_post``/``P_post``. What differs, and why:

* ``x`` is the nominal state [p, v_B, q, ω, θ], shape (13 + P,), with the P estimated
  quantities (θ, then any nuisance ones: `mavsysid.vehicle.parameters`) in SI units,
  while ``P`` is the covariance of the error state (12 + P, 12 + P) of
  `mavsysid.vehicle.linearization`: the attitude error is a 3-vector
  (``q = q̂ ⊗ Exp(δφ)``) and the quantities' errors are in units of ``theta_scale`` (the
  prior), so P stays well conditioned at any vehicle scale.
* ``predict(u, dt, u_next)`` integrates the nonlinear model (the model's RK4,
  `mavsysid.vehicle.dynamics.rk4_linear_step_kernel`, rotor speeds linear between ``u``
  and ``u_next``) and propagates P with the shared linearisation (paper Eq. prior);
  ``update(z)`` takes z = [p (3), q (4)] and applies the correction multiplicatively to
  the attitude (Joseph form, with the error-state reset).

The covariance step and the measurement (H, residual) are the planner's too
(`mavsysid.vehicle.covariance`), so the belief the planner predicts is this filter's P.
The arithmetic lives in compiled kernels shared by the per-step methods and by `run`,
which filters a whole flight in one compiled loop.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from mavsysid.estimation.filter.imu_measurement import (
    ImuSteps,
    imu_index,
    imu_steps,
    imu_update_kernel,
)
from mavsysid.estimation.flight import FlightData, Imu, step_process_noise
from mavsysid.estimation.results import EstimationHistory, ParameterEstimate
from mavsysid.vehicle.config import VehicleConfig
from mavsysid.vehicle.covariance import (
    pose_residual_kernel,
    predict_covariance_kernel,
    update_covariance_kernel,
)
from mavsysid.vehicle.dynamics import STATE_DIM, rk4_linear_step_kernel
from mavsysid.vehicle.linearization import (
    MEAS_DIM,
    ErrorStateModel,
    extra_columns_kernel,
    extra_wrench_kernel,
    jacobian_kernel,
    transition_kernel,
)
from mavsysid.vehicle.parameters import PAPER_THETA, quantity_names
from mavsysid.vehicle.rotation import (
    exp_kernel,
    multiply_kernel,
    quat_log,
    quat_multiply,
    quat_to_matrix,
)

from mavsysid.errors import JobFailedError, LogFormatError

__all__ = ["FilterOverflow", "FilterRun", "ParameterEKF"]


@dataclass(frozen=True)
class FilterRun:
    """A whole flight filtered: the history, and the full state at every sample.

    Attributes
    ----------
    history : EstimationHistory
    states : ndarray, shape (N, 13)
        Filtered model states after each update.
    estimate : ParameterEstimate
        Final θ and its covariance, SI.
    log_likelihood : float
        Log-likelihood of all innovations, Σ log N(y_k; 0, S_k).
    """

    history: EstimationHistory
    states: np.ndarray
    estimate: ParameterEstimate
    log_likelihood: float


@numba.njit(cache=True)
def _predict_kernel(x, P, n0, n1, w0, w1, b0, b1, dt, mass, r, eps, scale, Qc, A, G, F, Q):
    """Paper Eq. prior: x ← f-integrated, P ← F P Fᵀ + Q (F, Q at the step's start).

    The effects' wrench w0, w1 (6,) is a known input: it shifts the mean and does not
    enter F (its state derivatives are second order for the small effects it models). The
    nuisance quantities add their wrench b @ x_extra (b0, b1 of shape (6, E)) to it and
    their columns to F.
    """
    theta = x[13:]
    jacobian_kernel(x[:13], n0, theta, mass, r, eps, scale, A, G)
    extra_columns_kernel(b0, theta[3:6], mass, scale, A)
    transition_kernel(A, G, Qc, dt, F, Q)
    extras = theta[6:]
    wa, wb = np.empty(6), np.empty(6)
    extra_wrench_kernel(w0, b0, extras, wa)
    extra_wrench_kernel(w1, b1, extras, wb)
    state = np.empty(13)
    rk4_linear_step_kernel(x[:13], n0, n1, wa, wb, theta, dt, mass, r, eps, state)
    x[:13] = state
    predict_covariance_kernel(P, F, Q)


@numba.njit(cache=True)
def _update_kernel(x, P, z, R, scale, y, S, SI, K):
    """Measurement update with z = [p, q]; returns the NIS yᵀ S⁻¹ y.

    The covariance takes the shared Joseph-form step (paper Eq. posterior); the
    correction is applied multiplicatively to the attitude and the error state reset.
    """
    pose_residual_kernel(z, x, y)
    update_covariance_kernel(P, R, S, SI, K)
    _correct(x, P, K @ y, scale)
    return y @ SI @ y


@numba.njit(cache=True)
def _correct(x, P, dx, scale):
    """Apply an error-state correction dx (D,) to x, and reset P's attitude error to it."""
    # Multiplicative attitude correction and additive everything else.
    x[0:6] += dx[0:6]
    q = multiply_kernel(x[6:10], exp_kernel(dx[6:9]))
    x[6:10] = q / np.sqrt(np.sum(q * q))
    x[10:13] += dx[9:12]
    x[13:] += scale * dx[12:]
    # Error-state reset: the new attitude error is measured from the corrected nominal.
    n = P.shape[0]
    Gam = np.eye(n)
    d = dx[6:9]
    Gam[6, 7], Gam[6, 8] = 0.5 * d[2], -0.5 * d[1]
    Gam[7, 6], Gam[7, 8] = -0.5 * d[2], 0.5 * d[0]
    Gam[8, 6], Gam[8, 7] = 0.5 * d[1], -0.5 * d[0]
    P[:] = Gam @ P @ Gam.T
    P[:] = 0.5 * (P + P.T)


@numba.njit(cache=True)
def _imu_step(k, t, n, w, basis, x0, x, P, mass, r, eps, scale, Qc, F, A, G, imu_z, imu_info,
              imu_index, imu_position):
    """The IMU's update at step k (after its prediction from x0); returns (NIS, log N)."""
    nis, log_n, dx = imu_update_kernel(
        x, P, x0, n[k - 1], n[k], w[k - 1], w[k], basis[k - 1], basis[k], F, A, G, Qc[k - 1],
        t[k] - t[k - 1], imu_z[k], imu_info[k], mass, r, eps, scale, imu_index, imu_position)
    if np.isfinite(nis):
        _correct(x, P, dx, scale)
    return nis, log_n


@numba.njit(cache=True)
def _filter_kernel(t, z, n, w, basis, x, P, mass, r, eps, scale, Qc, R, imu_z, imu_info,
                   imu_index, imu_position, out_x, out_sigma, out_innov, out_nis, out_imu_nis):
    """Filter samples 1..N-1 (sample 0 initialised x, P); histories into the out arrays.

    w (N, 6) is the effects' extra body force and torque at every sample (zeros: none);
    basis (N, 6, E) the nuisance quantities' wrench per unit value; Qc (N, 6, 6) the
    process-noise density of each step (from sample k − 1 to k). imu_z (N, 6), imu_info
    (N, 9): the IMU's mean readings per step (`mavsysid.estimation.filter.imu_measurement`,
    NaN: none), fused right after each prediction; imu_index (9,), imu_position (3,) where
    its quantities sit and its stated offset.

    Returns the log-likelihood of the innovations, Σ log N(y_k; 0, S_k), pose and IMU.
    """
    log_likelihood = 0.0
    d = P.shape[0]
    p = scale.shape[0]
    A = np.empty((d, d))
    G = np.empty((d, 6))
    F = np.empty((d, d))
    Q = np.empty((d, d))
    y = np.empty(6)
    S = np.empty((6, 6))
    SI = np.empty((6, 6))
    K = np.empty((d, 6))
    out_x[0] = x
    for j in range(p):
        out_sigma[0, j] = np.sqrt(P[12 + j, 12 + j]) * scale[j]
    out_innov[0] = 0.0
    out_nis[0] = np.nan
    out_imu_nis[0] = np.nan
    for k in range(1, t.shape[0]):
        reads_imu = np.isfinite(imu_z[k, 0]) or np.isfinite(imu_z[k, 3])
        x0 = x.copy() if reads_imu else x
        _predict_kernel(x, P, n[k - 1], n[k], w[k - 1], w[k], basis[k - 1], basis[k],
                        t[k] - t[k - 1], mass, r, eps, scale, Qc[k - 1], A, G, F, Q)
        # A diverged state overflows: the update would invert a NaN S, or normalise the
        # attitude to zero and divide by it next step. Stop; the caller refuses the run.
        if not (np.isfinite(np.sum(x)) and np.isfinite(np.trace(P))):
            x[:] = np.nan
            return np.nan
        out_imu_nis[k] = np.nan
        if reads_imu:
            out_imu_nis[k], log_n = _imu_step(k, t, n, w, basis, x0, x, P, mass, r, eps, scale,
                                              Qc, F, A, G, imu_z, imu_info, imu_index,
                                              imu_position)
            log_likelihood += log_n
        out_nis[k] = _update_kernel(x, P, z[k], R, scale, y, S, SI, K)
        if not (np.isfinite(out_nis[k]) and abs(np.sum(x[6:10] * x[6:10]) - 1.0) < 1e-6):
            x[:] = np.nan
            return np.nan
        log_det = 2.0 * np.sum(np.log(np.diag(np.linalg.cholesky(S))))
        log_likelihood -= 0.5 * (out_nis[k] + log_det + 6.0 * np.log(2.0 * np.pi))
        out_innov[k] = y
        out_x[k] = x
        for j in range(p):
            out_sigma[k, j] = np.sqrt(P[12 + j, 12 + j]) * scale[j]
    return log_likelihood


class ParameterEKF(ExtendedKalmanFilter):
    """EKF over the state [p, v_B, q, ω] augmented with θ, driven by logged rotor speeds.

    Parameters
    ----------
    config : VehicleConfig
        Mass, rotor geometry and process-noise densities (``[noise]``).
    prior : ParameterEstimate
        Prior θ (SI) and its covariance; its values also set the θ error units.
    measurement_sigma : tuple of 2 float
        Position σ (m) and attitude σ (rad) of the pose measurements.
    read_imu : bool, optional
        Whether `run` reads the flight's IMU (`mavsysid.estimation.filter.imu_measurement`).
        None (default): each sensor whose biases are among the estimated quantities (the
        config of `mavsysid.estimation.answer.with_imu_quantities`); True: every logged
        sensor, a bias not estimated taken as 0; False: the pose alone.

    The quantities are θ and the config's ``extra_quantities`` (their prior the last
    entries of ``prior``).
    """

    def __init__(
        self, config: VehicleConfig, prior: ParameterEstimate,
        measurement_sigma: tuple[float, float], read_imu: bool | None = None,
    ) -> None:
        extras = tuple(config.extra_quantities)
        if prior.value.shape != (len(PAPER_THETA) + len(extras),):
            raise ValueError(f"prior of {prior.value.size} quantities for θ and "
                             f"{len(extras)} nuisance quantities")
        # A quantity's unit: its prior value, or its prior σ where the value is 0.
        scale = np.abs(prior.value)
        scale = np.where(scale > 0.0, scale, np.where(prior.sigma > 0.0, prior.sigma, 1.0))
        self.model = ErrorStateModel.for_vehicle(config, scale, extras)
        dim = self.model.dim
        super().__init__(dim_x=dim, dim_z=MEAS_DIM)
        self.prior = prior
        self._kernel_args = self.model.kernel_args()
        self._Qc = self.model.process_noise_density()
        sp, sa = measurement_sigma
        self.R = np.diag([sp**2] * 3 + [sa**2] * 3)
        self.x = np.concatenate([np.zeros(STATE_DIM), prior.value])
        self.x[6] = 1.0
        s = self.model.theta_scale
        self.P = np.zeros((dim, dim))
        self.P[12:, 12:] = prior.covariance / np.outer(s, s)
        self.K = np.zeros((dim, MEAS_DIM))
        self.y = np.zeros(MEAS_DIM)
        self._G = np.zeros((dim, 6))
        self._A = np.zeros((dim, dim))
        self._no_basis = np.zeros((6, len(extras)))
        self.read_imu = read_imu
        self._step: tuple | None = None  # the last prediction's start, for `update_imu`

    # -- filterpy API -----------------------------------------------------------------

    def initialize(
        self, position: np.ndarray, quaternion: np.ndarray, velocity_body: np.ndarray,
        body_rates: np.ndarray, state_sigma: tuple[float, float, float, float],
    ) -> None:
        """Set the model state and its σ (position m, velocity m/s, attitude rad, rate rad/s)."""
        self.x[0:3] = position
        self.x[3:6] = velocity_body
        self.x[6:10] = quaternion / np.linalg.norm(quaternion)
        self.x[10:13] = body_rates
        for i, sigma in enumerate(state_sigma):
            self.P[3 * i:3 * i + 3, 3 * i:3 * i + 3] = np.eye(3) * sigma**2
        self.x_post, self.P_post = self.x.copy(), self.P.copy()

    def predict(
        self, u: np.ndarray, dt: float, u_next: np.ndarray | None = None,
        wrench: np.ndarray | None = None, wrench_next: np.ndarray | None = None,
    ) -> None:
        """Propagate over ``dt`` s with rotor speeds ``u`` (k,) (linear to ``u_next``).

        ``wrench`` (6,): extra body force (N) and torque (N·m) of known model effects at
        the step's start (linear to ``wrench_next``); zero by default.
        """
        u = np.ascontiguousarray(u, dtype=float)
        u1 = u if u_next is None else np.ascontiguousarray(u_next, dtype=float)
        w0 = np.zeros(6) if wrench is None else np.ascontiguousarray(wrench, dtype=float)
        w1 = w0 if wrench_next is None else np.ascontiguousarray(wrench_next, dtype=float)
        mass, r, eps, scale = self._kernel_args
        self._step = (self.x.copy(), u, u1, w0, w1, float(dt))
        _predict_kernel(self.x, self.P, u, u1, w0, w1, self._no_basis, self._no_basis,
                        float(dt), mass, r, eps, scale, self._Qc, self._A, self._G, self.F,
                        self.Q)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def update_imu(self, z: np.ndarray, variance: np.ndarray | None = None,
                   weight: tuple[float, float] = (1.0, 1.0), span: float | None = None,
                   position: np.ndarray | None = None) -> float:
        """Correct with the IMU's mean reading over the last `predict` step; call it before
        that step's pose `update` (the module `mavsysid.estimation.filter.imu_measurement`).

        Parameters
        ----------
        z : ndarray, shape (6,)
            Mean gyro (rad/s) and specific force (m/s²), body FLU; NaN for a sensor
            without samples in the step.
        variance : ndarray, shape (6,), optional
            Sensor-noise variance of each mean; default the config's per-sample σ².
        weight : tuple of 2 float
            ᾱ of the gyro's and the accelerometer's samples: the weight of the step's end.
        span : float, optional
            Time the accelerometer's samples span, s; default the step.
        position : ndarray, shape (3,), optional
            The IMU's stated offset from the centre of gravity, m (default: the ``imu_x..z``
            quantities, else the centre of gravity).

        Returns
        -------
        float
            The NIS yᵀ S⁻¹ y (NaN: no reading).
        """
        if self._step is None:
            raise RuntimeError("update_imu follows a predict()")
        x0, u0, u1, w0, w1, dt = self._step
        nz = self.model.config.noise
        info = np.zeros(9)
        info[0:2] = weight
        info[2:8] = (np.repeat([nz.gyro_sigma**2, nz.accel_sigma**2], 3) if variance is None
                     else variance)
        info[8] = dt if span is None else span
        index, stated = imu_index(self.model.extras, position)
        mass, r, eps, scale = self._kernel_args
        nis, _, dx = imu_update_kernel(
            self.x, self.P, x0, u0, u1, w0, w1, self._no_basis, self._no_basis, self.F, self._A,
            self._G, self._Qc, dt, np.ascontiguousarray(z, dtype=float), info, mass, r, eps,
            scale, index, stated)
        if np.isfinite(nis):
            _correct(self.x, self.P, dx, scale)
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        return float(nis)

    def update(self, z: np.ndarray, R: np.ndarray | None = None) -> None:  # type: ignore[override]
        """Correct with a pose z = [x, y, z, qw, qx, qy, qz] (m, unit quaternion)."""
        R = self.R if R is None else np.asarray(R, dtype=float)
        self.S = np.empty((MEAS_DIM, MEAS_DIM))
        self.SI = np.empty((MEAS_DIM, MEAS_DIM))
        _update_kernel(self.x, self.P, np.ascontiguousarray(z, dtype=float), R,
                       self._kernel_args[3], self.y, self.S, self.SI, self.K)
        self.z = np.asarray(z, dtype=float).copy()
        self._log_likelihood = None
        self._likelihood = None
        self._mahalanobis = None
        self.x_post, self.P_post = self.x.copy(), self.P.copy()

    # -- results ----------------------------------------------------------------------

    @property
    def theta(self) -> np.ndarray:
        """Current estimate of θ and the nuisance quantities, SI, shape (P,)."""
        return self.x[STATE_DIM:].copy()

    @property
    def theta_covariance(self) -> np.ndarray:
        """Their current covariance, SI, shape (P, P)."""
        return self.model.parameter_covariance_si(self.P)

    @property
    def estimate(self) -> ParameterEstimate:
        """The current estimate with its covariance and the quantities' names."""
        return ParameterEstimate(self.theta, self.theta_covariance,
                                 quantity_names(self.model.extras))

    def start_segment(self, flight: FlightData, i: int,
                      state_sigma: tuple[float, float, float, float]) -> None:
        """Restart the model state from samples ``i``, ``i + 1`` of ``flight`` (finite
        differences), with σ ``state_sigma``; θ and its covariance kept, the states'
        cross-covariance with θ dropped. The difference spans ≥ half the median step."""
        t = flight.t
        step = 0.5 * float(np.median(np.diff(t[i:i + 64])))
        j = min(max(int(np.searchsorted(t, t[i] + step)), i + 1), t.size - 1)
        dt0 = t[j] - t[i]
        q0, q1 = flight.quaternion[i], flight.quaternion[j]
        rates = quat_log(quat_multiply(q0 * [1, -1, -1, -1], q1)) / dt0
        v_world = (flight.position[j] - flight.position[i]) / dt0
        v_body = quat_to_matrix(q0).T @ v_world
        self.P[:12, :] = 0.0
        self.P[:, :12] = 0.0
        self.initialize(flight.position[i], q0, v_body, rates, state_sigma)

    def reads(self, imu: Imu | None) -> Imu | None:
        """The part of ``imu`` this filter reads (``read_imu``), None: none of it.

        Parameters
        ----------
        imu : Imu or None
            The flight's IMU.
        """
        if imu is None or self.read_imu is False:
            return None
        if self.read_imu is None:
            names = set(quantity_names(self.model.extras))
            gyro = {f"gyro_bias_{a}" for a in "xyz"} <= names
            accel = {f"accel_bias_{a}" for a in "xyz"} <= names and (
                imu.position is not None or {f"imu_{a}" for a in "xyz"} <= names)
            imu = replace(imu, gyro=imu.gyro if gyro else None,
                          accel=imu.accel if accel else None)
        return None if imu.gyro is None and imu.accel is None else imu

    def imu_steps(self, flight: FlightData) -> tuple[ImuSteps, np.ndarray, np.ndarray]:
        """The IMU's readings per step of ``flight`` that `run` fuses, and where its
        quantities sit (`mavsysid.estimation.filter.imu_measurement.imu_index`).

        Parameters
        ----------
        flight : FlightData
            The flight `run` filters.
        """
        imu = self.reads(flight.imu)
        index, position = imu_index(self.model.extras, None if imu is None else imu.position)
        return imu_steps(flight.t, imu, self.model.config.noise), index, position

    def run(
        self, flight: FlightData, state_sigma: tuple[float, float, float, float],
        wrench: np.ndarray | None = None,
    ) -> FilterRun:
        """Filter a whole flight: initialise from its first samples, then predict/update.

        The initial velocity and body rates come from finite differences of the first two
        poses; ``state_sigma`` gives their initial σ (position, velocity, attitude, rate).
        A flight of several segments (``flight.segment_starts``) restarts the states at
        each segment's start and carries θ and its covariance across the gap.
        ``wrench`` (N, 6): extra body force (N) and torque (N·m) of known model effects at
        every sample (`mavsysid.estimation.filter.likelihood.ModelTerms`); zeros by default.
        ``flight`` is in the model's terms (effects' pose and rotor-speed channels applied).
        """
        t = np.ascontiguousarray(flight.t, dtype=float)
        if t.size < 2 or not np.all(np.diff(t) > 0.0):
            # Readers drop repeated stamps; a zero step would divide by zero in `start_segment`.
            raise LogFormatError(f"{flight.source}: the sample times must increase strictly")
        self.start_segment(flight, 0, state_sigma)
        z = np.ascontiguousarray(np.hstack([flight.position, flight.quaternion]))
        n = np.ascontiguousarray(flight.rotor_speeds, dtype=float)
        N = t.size
        out_x = np.empty((N, STATE_DIM + self.model.parameter_count))
        out_sigma = np.empty((N, self.model.parameter_count))
        out_innov = np.full((N, MEAS_DIM), np.nan)  # NaN: not reached (`FilterOverflow`)
        out_nis = np.empty(N)
        out_imu_nis = np.full(N, np.nan)
        imu, imu_index_, imu_position = self.imu_steps(flight)
        mass, r, eps, scale = self._kernel_args
        w = np.zeros((N, 6)) if wrench is None else np.ascontiguousarray(wrench, dtype=float)
        if w.shape != (N, 6):
            raise ValueError(f"wrench of shape ({N}, 6) expected, got {w.shape}")
        # Each step's process noise: the configured density plus the wrench error that
        # interpolating slow rotor-speed inputs leaves (`mavsysid.estimation.flight`).
        Qc = step_process_noise(self._Qc, t, n, flight.inputs, self.prior.value, r, eps)
        basis = np.ascontiguousarray(self.model.extra_basis(
            flight.pose_states(), n, self.prior.value, t - t[0]) if self.model.extras
            else np.zeros((N, 6, 0)))
        try:
            log_likelihood = 0.0
            for i, (a, b) in enumerate(flight.segment_bounds):
                if i:  # after a gap: the vehicle states restart, θ and its σ carry on
                    self.start_segment(flight, a, state_sigma)
                log_likelihood += _filter_kernel(
                    t[a:b], z[a:b], n[a:b], w[a:b], basis[a:b], self.x, self.P, mass, r, eps,
                    scale, Qc[a:b], self.R, imu.z[a:b], imu.info[a:b], imu_index_,
                    imu_position, out_x[a:b], out_sigma[a:b], out_innov[a:b], out_nis[a:b],
                    out_imu_nis[a:b])
        except (ZeroDivisionError, np.linalg.LinAlgError) as error:
            # A model that cannot follow the log (wrong vehicle or rotor order) drives the
            # state to overflow; the compiled kernel then fails on a division or on S.
            raise FilterOverflow(flight, out_innov) from error
        if not (np.all(np.isfinite(self.x)) and np.all(np.isfinite(self.P))):
            raise FilterOverflow(flight, out_innov)
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        history = EstimationHistory(
            t=t, theta=out_x[:, STATE_DIM:], theta_sigma=out_sigma, position=out_x[:, 0:3],
            quaternion=out_x[:, 6:10], innovation=out_innov, nis=out_nis,
            imu_nis=out_imu_nis if imu.steps else None,
        )
        return FilterRun(history, out_x[:, :STATE_DIM], self.estimate, log_likelihood)


class FilterOverflow(JobFailedError):
    """The filter's state overflowed; ``innovation`` (n, 6): the innovations before it."""

    def __init__(self, flight: FlightData, innovation: np.ndarray) -> None:
        super().__init__(f"{flight.source}: the parameter filter diverged (the model cannot "
                         "follow this log's motion with these rotor speeds); check --vehicle, "
                         "its rotor order and the log's motor outputs")
        self.innovation = innovation[np.all(np.isfinite(innovation), axis=1)]
