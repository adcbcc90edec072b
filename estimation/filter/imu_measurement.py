"""The autopilot's IMU as a measurement of the parameter EKF: readings per filter step, and
their update.

The filter steps from pose sample k − 1 to k (`mavsysid.estimation.filter.ekf`). Each IMU
sample is used once, at the step whose interval (t_{k−1}, t_k] holds it: the samples of a
step are **averaged** (`imu_steps`), whatever the IMU's rate. An IMU faster than the pose
gives several samples a step; a slower one gives one sample to some steps and none to
others (those steps have no IMU update). Interpolating a slow IMU to every t_k instead
would use each sample in several steps, measurements whose errors are one and the same,
and the filter would count them as independent.

**What the average measures.** A sample at t_{k−1} + α Δt reads h(x(t)) plus its bias
and noise, where h is the ideal reading of `mavsysid.vehicle.imu.imu_kernel` (ω, and the
specific force at the IMU: F_B/m with the rotors', the effects' and the nuisance
quantities' force, plus ω̇ × p + ω × (ω × p)). Along the step the state is close to a
straight line, so the average of the samples reads

    h̄ = (1 − ᾱ) h(x_{k−1}) + ᾱ h(x_k) + b,

ᾱ the samples' mean α, x_{k−1} the state the step started from, b the quantities
``gyro_bias_*``, ``accel_bias_*``. The lever arm p is the stated ``imu.position``, else
the quantities ``imu_x..z``. H = ∂h̄/∂δx_k by central differences (h is at most
quadratic in v_B, ω, p and the biases, so those columns are exact; J enters through
J⁻¹), the start's through F⁻¹ of the step (δx_{k−1} = F⁻¹ δx_k to first order). An
autopilot's low-pass delays what it logs: a 2-pole Butterworth at f_c Hz (ArduPilot's
``LowPassFilter2p``) by √2 / (2π f_c) s at low frequency, taken off the sample times.

**Its noise.** Consecutive samples of a low-passed IMU are correlated: an average of M
samples dt apart is worth n_eff = M · min(1, 2 B dt) independent ones, B = 1.11 f_c the
noise bandwidth of the 2-pole low-pass (its equivalent rectangular bandwidth), B the
Nyquist rate 1/(2 dt) for raw samples or an unknown filter. R = σ² / n_eff per axis, σ
the per-sample σ of the vehicle's ``[noise]``; n_eff < 1 when the pose is faster than
the filter's bandwidth, so that the steps together count the information the band holds.
Two parts of the vehicle's motion are noise to this measurement:

* The accelerometer feels the unmodelled force, the process noise w_F of density Q_c
  that also drives the velocity: over the samples' span T = M dt its mean adds
  Q_F / (m² T) to R, and it is correlated with the step's process noise,
  E[δx_k v_Fᵀ] = C = (L / (m T)) (I + A L/2) G Q_c[:, F], L = min(T, Δt). The update
  takes C into S, K and the Joseph form; fused right after the prediction (before the
  pose's update) C is exactly that covariance. Without it the pose and the accelerometer
  would each count the same unmodelled force, and θ's σ would come out up to √2 small.
* ω between x_{k−1} and x_k strays from the straight line by the moment noise: a
  Brownian bridge, Q_M / J² · Δt · ᾱ (1 − ᾱ) added to the gyro's R (0 for samples at t_k).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from mavsysid.estimation.flight import Imu, ImuSeries
from mavsysid.vehicle.config import NoiseConfig
from mavsysid.vehicle.imu import ImuBias, ImuOffset, imu_kernel
from mavsysid.vehicle.linearization import extra_wrench_kernel
from mavsysid.vehicle.parameters import PAPER_THETA, EstimatedQuantity

__all__ = ["IMU_DIM", "LOWPASS_BANDWIDTH", "ImuSteps", "imu_index", "imu_steps",
           "imu_update_kernel", "lowpass_delay"]

#: Rows of an IMU measurement: gyro (rad/s), then specific force (m/s²), body FLU.
IMU_DIM = 6

#: Noise bandwidth of a 2-pole Butterworth low-pass per Hz of its cutoff, (π/4) / sin(π/4).
LOWPASS_BANDWIDTH = (math.pi / 4.0) / math.sin(math.pi / 4.0)

#: Columns of `ImuSteps.info`.
_WEIGHT_GYRO, _WEIGHT_ACCEL, _VARIANCE, _SPAN = 0, 1, 2, 8
_INFO_DIM = 9


def lowpass_delay(cutoff_hz: float | None) -> float:
    """Low-frequency group delay of a 2-pole Butterworth low-pass, √2 / (2π f_c), s.

    Parameters
    ----------
    cutoff_hz : float or None
        The autopilot's cutoff, Hz; 0 or None: no (known) filter, no delay.
    """
    if cutoff_hz is None or not cutoff_hz > 0.0:
        return 0.0
    return math.sqrt(2.0) / (2.0 * math.pi * cutoff_hz)


@dataclass(frozen=True)
class ImuSteps:
    """The IMU's readings per filter step (N pose samples).

    Attributes
    ----------
    z : ndarray, shape (N, 6)
        Mean gyro (rad/s) and specific force (m/s²) of the samples in (t_{k−1}, t_k];
        NaN where a sensor has none.
    info : ndarray, shape (N, 9)
        Per step: the weight ᾱ of x_k in the gyro's and in the accelerometer's mean, the
        sensor-noise variance of each of the six means (σ² / n_eff), and the span T of the
        accelerometer's samples, s.
    """

    z: np.ndarray
    info: np.ndarray

    @classmethod
    def empty(cls, count: int) -> ImuSteps:
        """No IMU reading at any of ``count`` steps.

        Parameters
        ----------
        count : int
            Steps of the flight.
        """
        return cls(np.full((count, IMU_DIM), np.nan), np.zeros((count, _INFO_DIM)))

    @property
    def steps(self) -> int:
        """How many steps have a reading."""
        return int(np.sum(np.any(np.isfinite(self.z), axis=1)))


def _bandwidth(series: ImuSeries, dt: float) -> float:
    """The noise bandwidth of the samples, Hz: the low-pass's, at most the Nyquist rate."""
    nyquist = 0.5 / dt
    cutoff = series.cutoff_hz
    if cutoff is None or not cutoff > 0.0:
        return nyquist
    return min(nyquist, LOWPASS_BANDWIDTH * cutoff)


def _sensor_steps(t: np.ndarray, series: ImuSeries, sigma: float, rows: slice,
                  weight_column: int, steps: ImuSteps) -> None:
    """One sensor's samples binned into the steps, written into ``steps`` (module doc)."""
    ok = np.all(np.isfinite(series.values), axis=1)
    ts, values = np.asarray(series.t, float)[ok], np.asarray(series.values, float)[ok]
    if ts.size < 2:
        return
    dt = float(np.median(np.diff(ts)))
    if not dt > 0.0:
        return
    te = ts - lowpass_delay(series.cutoff_hz)
    k = np.searchsorted(t, te, side="left")
    keep = (k >= 1) & (k < t.size)
    k, te, values = k[keep], te[keep], values[keep]
    count = np.bincount(k, minlength=t.size).astype(float)
    has = count > 0
    for i in range(3):
        mean = np.bincount(k, weights=values[:, i], minlength=t.size)
        steps.z[has, rows.start + i] = mean[has] / count[has]
    alpha = (te - t[k - 1]) / (t[k] - t[k - 1])
    steps.info[has, weight_column] = (np.bincount(k, weights=alpha, minlength=t.size)[has]
                                      / count[has])
    n_eff = count[has] * min(1.0, 2.0 * _bandwidth(series, dt) * dt)
    for i in range(3):
        steps.info[has, _VARIANCE + rows.start + i] = sigma**2 / n_eff
    if rows.start == 3:
        steps.info[has, _SPAN] = count[has] * dt


def imu_steps(t: np.ndarray, imu: Imu | None, noise: NoiseConfig) -> ImuSteps:
    """The IMU's readings at every filter step of a flight sampled at ``t`` (module doc).

    Parameters
    ----------
    t : ndarray, shape (N,)
        The pose's sample times, s, strictly increasing.
    imu : Imu or None
        The flight's IMU (None: none, every step without a reading).
    noise : NoiseConfig
        Per-sample σ of the gyro (rad/s) and the accelerometer (m/s²).

    Returns
    -------
    ImuSteps
    """
    t = np.asarray(t, dtype=float)
    steps = ImuSteps.empty(t.size)
    if imu is None:
        return steps
    for series, sigma, rows, column in ((imu.gyro, noise.gyro_sigma, slice(0, 3), _WEIGHT_GYRO),
                                        (imu.accel, noise.accel_sigma, slice(3, 6),
                                         _WEIGHT_ACCEL)):
        if series is not None:
            _sensor_steps(t, series, sigma, rows, column, steps)
    return steps


def imu_index(extras: tuple[EstimatedQuantity, ...], position: np.ndarray | None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Where the IMU's quantities sit among the estimated ones, for the kernels.

    Parameters
    ----------
    extras : tuple of EstimatedQuantity
        The nuisance quantities after θ.
    position : ndarray, shape (3,), or None
        The IMU's stated offset from the centre of gravity, m (None: from ``imu_x..z``,
        else the centre of gravity).

    Returns
    -------
    index : ndarray of int, shape (9,)
        Index into the quantities of the gyro's biases x, y, z, the accelerometer's, and
        the offset's coordinates; −1 where not estimated.
    position : ndarray, shape (3,)
        The stated offset (zeros where not stated), m.
    """
    index = np.full(9, -1, dtype=np.int64)
    for e, quantity in enumerate(extras):
        term = quantity.term
        at = len(PAPER_THETA) + e
        if isinstance(term, ImuBias):
            index[(0 if term.channel == "gyro" else 3) + term.axis] = at
        elif isinstance(term, ImuOffset) and position is None:
            index[6 + term.axis] = at
    stated = np.zeros(3) if position is None else np.asarray(position, dtype=float)
    return index, np.ascontiguousarray(stated)


@numba.njit(cache=True)
def _reading_kernel(x, n, w, basis, theta, mass, r, eps, index, position, out):
    """h(x) + b: the IMU's reading (6,) at state x with the quantities θ (SI)."""
    wrench = np.empty(6)
    extra_wrench_kernel(w, basis, theta[6:], wrench)
    p = position.copy()
    for i in range(3):
        if index[6 + i] >= 0:
            p[i] = theta[index[6 + i]]
    imu_kernel(x, n, theta[:6], mass, r, eps, wrench[:3], wrench[3:], p, out)
    for i in range(6):
        if index[i] >= 0:
            out[i] += theta[index[i]]


@numba.njit(cache=True)
def _reading_jacobian(x, n, w, basis, theta, mass, r, eps, index, position, scale, H):
    """∂(h + b)/∂δx at x into H (6, D) by central differences: δv, δω and the quantities
    (per scaled unit); position and attitude do not enter a body-frame reading."""
    H[:] = 0.0
    hp, hm = np.empty(6), np.empty(6)
    xs, th = x.copy(), theta.copy()
    step = 1e-4
    for c in range(6):  # δv (columns 3–5) and δω (9–11): state entries 3–5, 10–12
        col, entry = (3 + c, 3 + c) if c < 3 else (6 + c, 7 + c)
        xs[entry] = x[entry] + step
        _reading_kernel(xs, n, w, basis, theta, mass, r, eps, index, position, hp)
        xs[entry] = x[entry] - step
        _reading_kernel(xs, n, w, basis, theta, mass, r, eps, index, position, hm)
        xs[entry] = x[entry]
        H[:, col] = (hp - hm) / (2.0 * step)
    for j in range(theta.shape[0]):
        th[j] = theta[j] + step * scale[j]
        _reading_kernel(x, n, w, basis, th, mass, r, eps, index, position, hp)
        th[j] = theta[j] - step * scale[j]
        _reading_kernel(x, n, w, basis, th, mass, r, eps, index, position, hm)
        th[j] = theta[j]
        H[:, 12 + j] = (hp - hm) / (2.0 * step)


@numba.njit(cache=True)
def _rows(z):
    """The rows of z (6,) that hold a reading."""
    count = 0
    for i in range(IMU_DIM):
        if np.isfinite(z[i]):
            count += 1
    out = np.empty(count, dtype=np.int64)
    count = 0
    for i in range(IMU_DIM):
        if np.isfinite(z[i]):
            out[count] = i
            count += 1
    return out


@numba.njit(cache=True)
def _mean_model(x0, x, n0, n1, w0, w1, b0, b1, F, z, info, mass, r, eps, scale, index,
                position, rows, y, H):
    """The residual z − h̄ and H = ∂h̄/∂δx_k of the used ``rows`` (module doc)."""
    d = x.shape[0] - 1
    theta = x[13:]
    h0, h1 = np.empty(6), np.empty(6)
    H0, H1 = np.empty((6, d)), np.empty((6, d))
    _reading_kernel(x0[:13], n0, w0, b0, theta, mass, r, eps, index, position, h0)
    _reading_kernel(x[:13], n1, w1, b1, theta, mass, r, eps, index, position, h1)
    _reading_jacobian(x0[:13], n0, w0, b0, theta, mass, r, eps, index, position, scale, H0)
    _reading_jacobian(x[:13], n1, w1, b1, theta, mass, r, eps, index, position, scale, H1)
    H0F = np.linalg.solve(F.T, H0.T).T  # ∂h(x_{k−1})/∂δx_k = H0 F⁻¹
    for a in range(rows.shape[0]):
        i = rows[a]
        alpha = info[_WEIGHT_GYRO] if i < 3 else info[_WEIGHT_ACCEL]
        y[a] = z[i] - ((1.0 - alpha) * h0[i] + alpha * h1[i])
        H[a, :] = (1.0 - alpha) * H0F[i, :] + alpha * H1[i, :]


@numba.njit(cache=True)
def _noise(x, info, dt, mass, Qc, A, G, rows, R, C):
    """R of the used rows and C = E[δx_k vᵀ], the accelerometer's share of the step's
    process noise (module doc)."""
    R[:] = 0.0
    C[:] = 0.0
    J = x[16:19]
    span = info[_SPAN]
    overlap = min(span, dt) if span > 0.0 else 0.0
    alpha = info[_WEIGHT_GYRO]
    GQ = G @ np.ascontiguousarray(Qc[:, 0:3])
    AGQ = A @ GQ
    for a in range(rows.shape[0]):
        i = rows[a]
        R[a, a] = info[_VARIANCE + i]
        if i < 3:
            R[a, a] += Qc[3 + i, 3 + i] / (J[i] * J[i]) * dt * alpha * (1.0 - alpha)
        elif overlap > 0.0:
            R[a, a] += Qc[i - 3, i - 3] / (mass * mass * span)
            C[:, a] = overlap / (mass * span) * (GQ[:, i - 3] + 0.5 * overlap * AGQ[:, i - 3])


@numba.njit(cache=True)
def imu_update_kernel(x, P, x0, n0, n1, w0, w1, b0, b1, F, A, G, Qc, dt, z, info, mass, r,
                      eps, scale, index, position):
    """Joseph-form update with the IMU's mean reading of one step; returns (NIS, log N).

    Called right after the step's prediction (its F, A, G, Q_c; x0 the state it started
    from, n0/n1, w0/w1, b0/b1 the rotor speeds, known wrench and nuisance wrench basis at
    its ends). With noise v correlated with the prior error (C = E[δx vᵀ]):
    S = H P Hᵀ + H C + Cᵀ Hᵀ + R, K = (P Hᵀ + C) S⁻¹ and
    P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ − (I − K H) C Kᵀ − K Cᵀ (I − K H)ᵀ, in place; the
    caller applies the correction dx to x (multiplicatively to the attitude, as the
    pose's). A step without a reading leaves P as it was.

    Parameters
    ----------
    x : ndarray, shape (13 + Q,)
        The state after the step's prediction: position, attitude quaternion, velocity,
        body rates, then the Q estimated quantities (θ first), SI.
    P : ndarray, shape (D, D)
        Its error covariance (12 error states, then the quantities), updated in place.
    x0 : ndarray, shape (13 + Q,)
        The state the step started from.
    n0, n1 : ndarray, shape (k,)
        Rotor speeds at the step's ends, rad/s.
    w0, w1 : ndarray, shape (6,)
        The effects' known body force (N) and torque (N m) at the step's ends.
    b0, b1 : ndarray, shape (6, E)
        The nuisance quantities' wrench per unit value at the step's ends.
    F, A, G : ndarray, shape (D, D), (D, D), (D, 6)
        The step's transition, its continuous Jacobian and the noise input matrix.
    Qc : ndarray, shape (6, 6)
        The step's process-noise density (force, torque).
    dt : float
        The step's length, s.
    z : ndarray, shape (6,)
        The step's mean gyro (rad/s) and specific force (m/s²); NaN where not read.
    info : ndarray, shape (9,)
        The readings' weights within the step, their variances and span (`imu_steps`).
    mass : float
        kg.
    r, eps : ndarray
        The rotors' positions (m) and spin directions (`mavsysid.vehicle.dynamics`).
    scale : ndarray, shape (Q,)
        The quantities' scales (the filter's states are the quantities divided by them).
    index : ndarray of int, shape (9,)
        Where the IMU's quantities sit (`imu_index`).
    position : ndarray, shape (3,)
        The IMU's stated offset from the centre of gravity, m.

    Returns
    -------
    nis : float
        yᵀ S⁻¹ y (NaN: no reading).
    log_likelihood : float
        log N(y; 0, S) (0: no reading).
    dx : ndarray, shape (D,)
        The error-state correction to apply (zeros: no reading).
    """
    d = P.shape[0]
    rows = _rows(z)
    m = rows.shape[0]
    if m == 0:
        return np.nan, 0.0, np.zeros(d)
    y = np.empty(m)
    H = np.empty((m, d))
    _mean_model(x0, x, n0, n1, w0, w1, b0, b1, F, z, info, mass, r, eps, scale, index,
                position, rows, y, H)
    R = np.empty((m, m))
    C = np.empty((d, m))
    _noise(x, info, dt, mass, Qc, A, G, rows, R, C)
    PHC = P @ H.T + C
    S = H @ PHC + (H @ C).T + R
    SI = np.linalg.inv(S)
    K = PHC @ SI
    IKH = np.eye(d) - K @ H
    ICK = IKH @ C @ K.T
    P[:] = IKH @ P @ IKH.T + K @ R @ K.T - ICK - ICK.T
    P[:] = 0.5 * (P + P.T)
    nis = y @ SI @ y
    log_det = 2.0 * np.sum(np.log(np.diag(np.linalg.cholesky(S))))
    return nis, -0.5 * (nis + log_det + m * np.log(2.0 * np.pi)), K @ y
